"""Contour rings printed as one spiral: each ring blends into the next one inside it.

Joined by a straight connector, every ring ends where it began and steps across to the next
ring: the connector lies over both rings' bands (about W x W covered twice per ring) and its
ink is paid for by spreading all rings apart (the volume match), which leaves thin gaps
between them. Here a ring A that the next ring B lies inside (both closed, joinable by an
extruding connector) stops short of its end by a *blend* sector of arc length lambda, and
over that sector the path moves from A to B: the point at fraction u of the sector is
(1 - u) x A's point + u x B's corresponding point, projected onto the layer surface (a
point of it, so the blend stays on the layer). B is entered where the blend lands and
printed round until the sector where the blend arrived (its *footprint*, measured on B),
where B in turn blends into the next ring; so within the sector the blends of successive
rings run side by side one ring spacing apart, as everywhere else, and no ink lies twice.
Only the ends of the spiral leave a wedge: the first ring's sector starts lambda / 2 before
its start (half of the wedge covered twice, half left bare instead of all of it one way),
and the last ring of a component stops lambda / 2 before its footprint ends.
The first blend is 1-4 W long, longer on larger rings (``first_blend``; at most MAX_SHARE
of its ring); the next ones are the footprints, so the sector keeps its angle across a
disc's rings. The innermost ring of a spiral stops short of the distance peak; where it
leaves a bare spot (round ring) or strip (elongated ring) inside it, a line along its ridge
covers it (``ridge.py``), and a last loop narrower than W around that ridge is
left out for it. Only on components with one boundary loop (eq. 9's rings of a disc): a
band between two boundaries keeps its connectors.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from core.tolerance import tol
from slicer.toolpath.layer_nearest import face_tree, inside_barycentric, nearest_on_layer
from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.ordering import Piece
from slicer.toolpath.ridge import ridge_line
from slicer.toolpath.surface import boundary_loops

BLEND_RANGE = (1.0, 4.0)  # first blend's arc length, x W (``SpiralPlanner.first_blend``)
MAX_SHARE = 0.5  # a blend spans at most this share of its ring
NEAREST_FACES = 12  # faces (by centroid) tried when projecting a blended point


class Blend(NamedTuple):
    """Points of a blend on the layer surface.

    points: (k, 3) float64, mm; face: (k,) int32; bary: (k, 3) float64.
    """

    points: NDArray[np.float64]
    face: NDArray[np.int32]
    bary: NDArray[np.float64]


class Run(NamedTuple):
    """A piece as printed: its line points, then the blend into the next piece, if any.

    points: (k,) int64, point indices into the lines, in print order.
    line: int, the line id.
    tail: the blend printed after ``points`` (None: none).
    into_next: the next run starts where ``tail`` ends (no connector).
    """

    points: NDArray[np.int64]
    line: int
    tail: Blend | None
    into_next: bool


class _Polyline(NamedTuple):
    """A closed piece unrolled twice: index (2n + 1,), arc length (2n + 1,) mm, length mm."""

    idx: NDArray[np.int64]
    s: NDArray[np.float64]
    length: float


def _is_ring(piece: Piece) -> bool:
    """A closed line printed all the way round (ordering repeats its start at the end)."""
    return len(piece.points) >= 4 and int(piece.points[0]) == int(piece.points[-1])


def _unroll(points: NDArray[np.float64], idx: NDArray[np.int64]) -> _Polyline:
    """The ring ``idx`` (start repeated at the end) twice round, with arc lengths."""
    twice = np.concatenate([idx, idx[1:]])
    step = np.linalg.norm(np.diff(points[twice], axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(step)])
    return _Polyline(twice, s, float(s[len(idx) - 1]))


def _at(points: NDArray[np.float64], poly: _Polyline, sigma: NDArray[np.float64]
        ) -> NDArray[np.float64]:
    """(k, 3) mm, the points at arc lengths ``sigma`` (0 <= sigma <= 2 x length)."""
    xyz = points[poly.idx]
    return np.column_stack([np.interp(sigma, poly.s, xyz[:, c]) for c in range(3)])


def _arc_of(points: NDArray[np.float64], poly: _Polyline, p: NDArray[np.float64]) -> float:
    """Arc length (first time round) of the ring's point nearest to ``p``."""
    n = int(np.searchsorted(poly.s, poly.length)) + 1
    near = int(np.argmin(np.linalg.norm(points[poly.idx[:n]] - p, axis=1)))
    return float(poly.s[near])


class SpiralPlanner:
    """Decides the blends of one component's ordered pieces (module doc)."""

    def __init__(self, lines: SurfaceLines, vertices: NDArray[np.float64],
                 faces: NDArray[np.int32], width: NDArray[np.float64], reach: float) -> None:
        """``width``: (P,) mm per line point; ``reach``: connectors up to this x W extrude."""
        self.lines = lines
        self.vertices = vertices
        self.faces = faces
        self.width = width
        self.reach = reach
        self._tree: cKDTree | None = None

    def project(self, p: NDArray[np.float64]) -> Blend:
        """The points of the layer nearest to ``p`` ((k, 3) mm), with face and bary."""
        if self._tree is None:
            self._tree = face_tree(self.vertices, self.faces)
        q, nearest = nearest_on_layer(p, self.vertices, self.faces, NEAREST_FACES, self._tree)
        face = nearest.astype(np.int32)
        bary = inside_barycentric(q, self.vertices, self.faces, face)
        return Blend(q, face, bary)

    def blend(self, a: Piece, lam: float, extra: float, b: Piece
              ) -> tuple[Run, Piece, float] | None:
        """Ring ``a`` blending into ring ``b`` over ``lam`` mm ending ``extra`` mm past a's
        start: (a's run, b re-entered where the blend lands, b's footprint mm), or None
        where b does not run beside a along the sector."""
        pts = self.lines.points
        pa = _unroll(pts, np.asarray(a.points, dtype=np.int64))
        lam = min(lam, MAX_SHARE * pa.length)
        w = float(np.mean(self.width[a.points]))
        if lam < w or pa.length <= 0:
            return None
        start, end = pa.length - lam + extra, pa.length + extra
        step = float(np.median(np.diff(pa.s[: len(a.points)])))
        m = max(int(np.ceil(lam / max(step, tol.merge))), 2)
        u = np.arange(m) / m
        on_a = _at(pts, pa, start + lam * u)
        end_a = _at(pts, pa, np.array([end]))[0]
        # b entered at its point nearest the sector's end, running the way a runs
        ring_b = np.asarray(b.points[:-1], dtype=np.int64)
        land = int(np.argmin(np.linalg.norm(pts[ring_b] - end_a, axis=1)))
        ring_b = np.roll(ring_b, -land)
        tangent_a = end_a - _at(pts, pa, np.array([end - min(lam, 2.0 * step)]))[0]
        ahead = pts[ring_b[1:4]].mean(axis=0) - pts[ring_b[0]]
        if float(np.dot(tangent_a, ahead)) < 0:
            ring_b = np.concatenate([ring_b[:1], ring_b[1:][::-1]])
        b_idx = np.append(ring_b, ring_b[0])
        pb = _unroll(pts, b_idx)
        footprint = pb.length - _arc_of(pts, pb, on_a[0])
        if not 0.2 * lam * pb.length / pa.length <= footprint <= MAX_SHARE * pb.length:
            return None
        on_b = _at(pts, pb, pb.length - footprint * (1.0 - u))
        if float(np.linalg.norm(on_a - on_b, axis=1).max()) > self.reach * w:
            return None
        tail = self.project((1.0 - u)[:, None] * on_a + u[:, None] * on_b)
        flat = pa.idx[pa.s < start - tol.merge]
        return Run(flat, a.line, tail, True), Piece(b_idx, b.line), footprint

    def centre(self, ring: NDArray[np.int64], end: int, force: bool = False) -> Blend | None:
        """The line from point ``end`` of the innermost ``ring`` along its ridge, on the
        layer (``ridge.ridge_line``), or None."""
        pts = self.lines.points[ring]
        line = ridge_line(pts, float(np.mean(self.width[ring])), self.lines.points[end], force)
        return None if line is None else self.project(line)

    def first_blend(self, ring: Piece) -> float:
        """The first blend's length, mm: W sqrt(K max(ln K, 1)) within BLEND_RANGE x W, for
        K = L / (2 pi W) rings inside a ring of length L. The spiral's end wedges grow with
        the blend (about lambda x W / 2 bare or covered twice), the steepness of the K
        blends inside falls with it (their spacing s cos(atan(s / lambda_k)), lambda_k
        shrinking with the rings): the sum is least near this length."""
        w = float(np.mean(self.width[ring.points]))
        length = float(np.linalg.norm(np.diff(self.lines.points[ring.points], axis=0),
                                      axis=1).sum())
        k = max(length / (2.0 * np.pi * max(w, tol.merge)), 1.0)
        return float(np.clip(np.sqrt(k * max(np.log(k), 1.0)), *BLEND_RANGE)) * w

    def thin(self, ring: Piece) -> bool:
        """Whether a ring encloses no strip wider than W: its centroid lies within W / 2
        of it (a loop around the ridge at a layer's centre)."""
        pts = self.lines.points[ring.points]
        w = float(np.mean(self.width[ring.points]))
        return float(np.linalg.norm(pts - pts.mean(axis=0), axis=1).min()) < 0.5 * w

    def shortened(self, a: Piece, footprint: float | None, force: bool = False,
                  ridge: bool = True) -> Run:
        """The last ring of a spiral (a blend arrived at it, ``footprint`` mm): stopped half
        its footprint before its end, then the line along its ridge where it leaves a bare
        spot. A lone ring (no footprint, not ``force``) is printed whole, as it was: on the
        tips of a part (a ring or two across) the line's ink spread the ring outwards and
        doubled the width error where the flow fit had kept it. Without ``ridge`` (a line
        of its own runs along the ridge: contours fitted to an odd count) no line is added.
        """
        idx = np.asarray(a.points, dtype=np.int64)
        if footprint is None and not force:
            return Run(idx, a.line, None, False)
        if footprint is not None:
            pa = _unroll(self.lines.points, idx)
            idx = idx[pa.s[: len(idx)] < pa.length - 0.5 * footprint]
        ring = np.asarray(a.points, dtype=np.int64)
        return Run(idx, a.line, self.centre(ring, int(idx[-1]), force) if ridge else None, False)


def spiral_runs(planner: SpiralPlanner, pieces: list[Piece],
                can_join: Callable[[int, int], bool]) -> list[Run]:
    """The pieces as runs, consecutive joinable rings blended into a spiral.

    ``can_join(point_a, point_b) -> bool``: whether the linking would join two line points by
    an extruding connector (the rings are neighbours). The first ring of a spiral starts its
    blend half a blend before its start, the last stops half a footprint early when it ends
    the component. Open lines after the rings (the middle line of contours fitted to an odd
    count, ``ridge_fit.py``) follow the spiral as they are, and take the place of its
    ridge line.
    """
    n_rings = next((k for k, p in enumerate(pieces) if not _is_ring(p)), len(pieces))
    tail = [Run(np.asarray(p.points, dtype=np.int64), p.line, None, False)
            for p in pieces[n_rings:]]
    if tail and n_rings >= 1 and not any(_is_ring(p) for p in pieces[n_rings:]):
        return _spiral(planner, list(pieces[:n_rings]), can_join, ridge=False) + tail
    return _spiral(planner, list(pieces), can_join)


def _spiral(planner: SpiralPlanner, pieces: list[Piece], can_join: Callable[[int, int], bool],
            ridge: bool = True) -> list[Run]:
    """``spiral_runs`` of pieces that are all rings (else each as it is); ``ridge``: the
    last ring may add its ridge line."""
    if len(boundary_loops(planner.faces)) != 1 or not all(_is_ring(p) for p in pieces):
        # a band between two boundaries (fitted contours: where its line count changes the
        # rings' ink falls short and the connectors made it up, so blending pulled tau down
        # and the width error up, docs/benchmarks.md session 17), or an open line
        return [Run(np.asarray(p.points, dtype=np.int64), p.line, None, False) for p in pieces]
    runs: list[Run] = []
    force = (ridge and len(pieces) >= 2 and planner.thin(pieces[-1])
             and planner.centre(np.asarray(pieces[-2].points, dtype=np.int64),
                                int(pieces[-2].points[-1]), True) is not None)
    if force:
        # a loop around a ridge narrower than W: the ridge line of the ring around it
        # covers it instead (``centre``)
        pieces = pieces[:-1]
    footprint: float | None = None  # the blend that arrived at the current piece
    for k, piece in enumerate(pieces):
        nxt = pieces[k + 1] if k + 1 < len(pieces) else None
        done = None
        if (nxt is not None and _is_ring(piece) and _is_ring(nxt)
                and can_join(int(piece.points[-1]), int(nxt.points[0]))):
            lam = planner.first_blend(piece) if footprint is None else footprint
            extra = 0.5 * lam if footprint is None else 0.0
            done = planner.blend(piece, lam, extra, nxt)
        if done is not None:
            run, pieces[k + 1], footprint = done
            runs.append(run)
            continue
        if nxt is None and _is_ring(piece):
            runs.append(planner.shortened(piece, footprint, force, ridge))
        else:
            runs.append(Run(np.asarray(piece.points, dtype=np.int64), piece.line, None, False))
        footprint = None
    return runs
