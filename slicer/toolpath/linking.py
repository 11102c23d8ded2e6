"""Link the ordered lines of a layer component into few continuous extrusion paths.

Rule: the connector from the end of one line to the start of the next runs on the layer
surface: the straight chord where it stays on the layer (within CHORD_TOLERANCE; always for
points in edge-adjacent faces), else the shortest path on the mesh edge graph
(``scipy.sparse.csgraph.dijkstra`` from the three corners of the start face). If it is
shorter than ``extrude_factor`` (config ``join_factor``, default ``EXTRUDE_FACTOR`` = 3) times
the local toolpath width it extrudes and the two lines become one path: a stripe U-turn along
the boundary, a step to the next contour ring, or the offset between two stripes where a
branch point shifts the zig-zag (measured on socket stripe layers: 2 W joins left 8.8 starts
per component, 3 W 4.1; connectors then lay 25% of the volume instead of 23%, counted in the
volume match, ``LinkedPath.connector_segments``). Otherwise the nozzle stops extruding and
travels: it lifts along the printing direction to ``lift`` above the current layer (at least
one layer height), moves across at that clearance (points pushed up wherever they would come
closer to the layer than ``lift``), and plunges onto the next line's start. Travel waypoints
carry extrude=False and a path id of their own; a segment deposits iff both its ends extrude
and share a path id. Where joins up to 3 W keep a component's volume match from converging,
``build`` links it again with 2 W joins and keeps the better match.
Contour rings joined this way are blended into a spiral instead (``spiral.py``, config
``spiral_rings``): a straight step across lies over both rings.
``Joiner`` computes each connector once: the stripe ordering asks it which line ends can be
joined (``ordering._order_cover``) and the linking reuses the answers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from core.tolerance import tol
from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.ordering import Piece
from slicer.toolpath.spiral import Run, SpiralPlanner, spiral_runs

EXTRUDE_FACTOR = 3.0  # connectors shorter than this times W extrude (config: join_factor)
LIFT_FACTOR = 1.5  # travel clearance above the layer, in layer heights (>= 1)
CHORD_TOLERANCE = 0.02  # a chord within this x its limit of the layer counts as on it


@dataclass(frozen=True, eq=False)
class MeshGraph:
    """Edge graph of a layer mesh for on-surface connectors.

    Attributes:
        graph: (n, n) csr float64, mm, symmetric edge lengths.
        vertex_face: (n,) int32, one face containing each vertex.
        vertex_corner: (n,) int64, the vertex's corner (0, 1, 2) in that face.
    """

    graph: csr_matrix
    vertex_face: NDArray[np.int32]
    vertex_corner: NDArray[np.int64]


def mesh_graph(vertices: NDArray[np.float64], faces: NDArray[np.int32]) -> MeshGraph:
    """Build the edge graph of ``faces`` over ``vertices`` ((n, 3) mm)."""
    n = len(vertices)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    w = np.maximum(np.linalg.norm(vertices[e[:, 0]] - vertices[e[:, 1]], axis=1), tol.merge)
    g = coo_matrix(
        (np.r_[w, w], (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(n, n)
    ).tocsr()
    vf = np.full(n, -1, dtype=np.int64)
    vc = np.zeros(n, dtype=np.int64)
    flat = faces.ravel()
    order = np.arange(flat.size)[::-1]  # later writes win: any containing face will do
    vf[flat[order]] = order // 3
    vc[flat[order]] = order % 3
    return MeshGraph(g, vf.astype(np.int32), vc)


@dataclass(frozen=True, eq=False)
class Connector:
    """A path on the surface between two points.

    Attributes:
        points: (k, 3) float64, mm, interior points (mesh vertices), may be empty.
        face: (k,) int32.
        bary: (k, 3) float64.
        length: float, mm, total length including both ends.
    """

    points: NDArray[np.float64]
    face: NDArray[np.int32]
    bary: NDArray[np.float64]
    length: float


def surface_connector(
    mg: MeshGraph,
    vertices: NDArray[np.float64],
    faces: NDArray[np.int32],
    pa: NDArray[np.float64],
    fa: int,
    pb: NDArray[np.float64],
    fb: int,
    limit: float,
    lifter: Lifter | None = None,
) -> Connector | None:
    """Shortest on-surface connection from (pa in face fa) to (pb in face fb), or None.

    The straight chord is used when it stays on the surface: the two faces share an edge, or
    ``lifter`` finds the chord within ``CHORD_TOLERANCE`` of the layer (flat or gently
    curved there). Otherwise the path runs pa -> a corner of fa -> mesh edges (Dijkstra from
    the three corners) -> a corner of fb -> pb, the best of the 3 x 3 corner pairs. None if
    longer than ``limit`` (mm).
    """
    empty = Connector(np.zeros((0, 3)), np.zeros(0, np.int32), np.zeros((0, 3)), 0.0)
    chord = float(np.linalg.norm(pb - pa))
    if chord > limit:
        return None
    if fa == fb or np.intersect1d(faces[fa], faces[fb]).size >= 2:
        return Connector(empty.points, empty.face, empty.bary, chord)
    if lifter is not None:
        t = np.linspace(0.0, 1.0, 9)[1:-1, None]
        if lifter.max_offset((1.0 - t) * pa + t * pb) <= CHORD_TOLERANCE * max(limit, 1.0):
            return Connector(empty.points, empty.face, empty.bary, chord)
    ca, cb = faces[fa].astype(np.int64), faces[fb].astype(np.int64)
    off_a = np.linalg.norm(vertices[ca] - pa, axis=1)
    off_b = np.linalg.norm(vertices[cb] - pb, axis=1)
    dist, pred = dijkstra(
        mg.graph, indices=ca, limit=max(limit - off_a.min() - off_b.min(), 0.0),
        return_predecessors=True,
    )
    total = off_a[:, None] + dist[:, cb] + off_b[None, :]  # (3, 3) source x target corner
    i, j = np.unravel_index(int(np.argmin(total)), total.shape)
    length = float(total[i, j])
    if not np.isfinite(length) or length > limit:
        return None
    src, dst = int(ca[i]), int(cb[j])
    nodes = [dst]
    while nodes[-1] != src:
        nodes.append(int(pred[i, nodes[-1]]))
    path = np.array(nodes[::-1])
    bary = np.zeros((len(path), 3))
    bary[np.arange(len(path)), mg.vertex_corner[path]] = 1.0
    return Connector(vertices[path], mg.vertex_face[path], bary, length)


class Lifter:
    """Pushes travel points to a clearance above a layer along its growth direction.

    Args:
        vertices: (n, 3) float64, mm, layer vertices.
        normals: (n, 3) float64, unit growth direction per vertex.
    """

    def __init__(self, vertices: NDArray[np.float64], normals: NDArray[np.float64]) -> None:
        self.vertices = vertices
        self.normals = normals
        self.tree = cKDTree(vertices)

    def clear(self, points: NDArray[np.float64], lift: float, rounds: int = 4) -> tuple[
        NDArray[np.float64], NDArray[np.float64]
    ]:
        """Points moved up along the nearest vertex's normal until ``lift`` above the layer.

        Returns (points (k, 3) mm, normals (k, 3) unit of the nearest layer vertex).
        """
        p = np.array(points, dtype=np.float64, copy=True)
        nrm = np.zeros_like(p)
        for _ in range(rounds):
            _, nearest = self.tree.query(p)
            nrm = self.normals[nearest]
            h = np.einsum("ij,ij->i", p - self.vertices[nearest], nrm)
            short = h < lift * (1.0 - tol.slack)
            if not np.any(short):
                break
            p[short] += (lift - h[short])[:, None] * nrm[short]
        return p, nrm

    def max_offset(self, points: NDArray[np.float64]) -> float:
        """Largest distance (mm) of ``points`` from the layer's tangent planes at the nearest
        vertices (0 for points on a flat layer)."""
        _, nearest = self.tree.query(points)
        h = np.einsum("ij,ij->i", points - self.vertices[nearest], self.normals[nearest])
        return float(np.abs(h).max()) if len(h) else 0.0

    def travel(
        self, pa: NDArray[np.float64], pb: NDArray[np.float64], lift: float, step: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Travel waypoints from above ``pa`` to above ``pb`` (both on the layer).

        Returns (points (k, 3) mm, normals (k, 3) unit): the lift point, the traverse at
        ``lift`` clearance sampled every ``step`` mm, the plunge point; all extrude=False.
        """
        d = float(np.linalg.norm(pb - pa))
        k = max(int(np.ceil(d / max(step, tol.merge))), 1)
        t = np.linspace(0.0, 1.0, k + 1)[:, None]
        line = (1.0 - t) * pa + t * pb
        return self.clear(line, lift)


class Joiner:
    """On-surface connectors between line points of one component, computed once each.

    ``get(a, b)`` is the extruding connector from line point ``a`` to line point ``b`` (indices
    into ``lines``) or None when the surface path is longer than ``extrude_factor`` times
    the mean width at the two points; results are cached (both directions), so the ordering
    can test a join and the linking reuse it.
    """

    def __init__(self, lines: SurfaceLines, vertices: NDArray[np.float64],
                 faces: NDArray[np.int32], mg: MeshGraph, width: NDArray[np.float64],
                 lifter: Lifter, extrude_factor: float = EXTRUDE_FACTOR) -> None:
        self.lines = lines
        self.vertices = vertices
        self.faces = faces
        self.mg = mg
        self.width = width
        self.lifter = lifter
        self.extrude_factor = extrude_factor
        self._cache: dict[tuple[int, int], Connector | None] = {}

    def get(self, a: int, b: int) -> Connector | None:
        """Connector from point ``a`` to point ``b`` (interior points in that order)."""
        key = (min(a, b), max(a, b))
        if key not in self._cache:
            i, j = key
            w = 0.5 * (self.width[i] + self.width[j])
            self._cache[key] = surface_connector(
                self.mg, self.vertices, self.faces, self.lines.points[i],
                int(self.lines.face[i]), self.lines.points[j], int(self.lines.face[j]),
                self.extrude_factor * w, self.lifter)
        conn = self._cache[key]
        if conn is None or a <= b:
            return conn
        return Connector(conn.points[::-1], conn.face[::-1], conn.bary[::-1], conn.length)

    def prefetch(self, points: NDArray[np.int64]) -> None:
        """Decide at once, vectorised, the connectors between pairs of ``points`` (indices
        into ``lines``, e.g. all line ends) that are too long or whose straight chord stays
        on the layer (the first tests of ``surface_connector``); the others are left to
        ``get`` (a Dijkstra each)."""
        pts = np.unique(np.asarray(points, dtype=np.int64))
        if pts.size < 2:
            return
        xyz = self.lines.points[pts]
        reach = self.extrude_factor * float(self.width[pts].max())
        pairs = cKDTree(xyz).query_pairs(r=reach, output_type="ndarray")
        if pairs.size == 0:
            return
        i, j = pts[pairs[:, 0]], pts[pairs[:, 1]]  # i < j: pts sorted, pairs i < j
        pa, pb = self.lines.points[i], self.lines.points[j]
        chord = np.linalg.norm(pb - pa, axis=1)
        limit = self.extrude_factor * 0.5 * (self.width[i] + self.width[j])
        fa, fb = self.faces[self.lines.face[i]], self.faces[self.lines.face[j]]
        shared = (fa[:, :, None] == fb[:, None, :]).sum(axis=(1, 2))
        t = np.linspace(0.0, 1.0, 9)[1:-1]
        samples = (1.0 - t)[None, :, None] * pa[:, None] + t[None, :, None] * pb[:, None]
        _, near = self.lifter.tree.query(samples.reshape(-1, 3))
        h = np.einsum("ij,ij->i", samples.reshape(-1, 3) - self.lifter.vertices[near],
                      self.lifter.normals[near]).reshape(len(i), -1)
        flat = np.abs(h).max(axis=1) <= CHORD_TOLERANCE * np.maximum(limit, 1.0)
        empty = (np.zeros((0, 3)), np.zeros(0, np.int32), np.zeros((0, 3)))
        for k in np.flatnonzero(chord > limit).tolist():
            self._cache[(int(i[k]), int(j[k]))] = None
        for k in np.flatnonzero((chord <= limit) & ((shared >= 2) | flat)).tolist():
            self._cache[(int(i[k]), int(j[k]))] = Connector(*empty, float(chord[k]))

    def can_join(self, a: int, b: int) -> bool:
        """True if points ``a`` and ``b`` have an extruding connector."""
        return self.get(a, b) is not None


@dataclass(frozen=True, eq=False)
class LinkedPath:
    """A component's waypoints in print order.

    Attributes:
        points: (N, 3) float64, mm.
        face: (N,) int32, face on the layer, -1 for travel points off the surface.
        bary: (N, 3) float64, barycentrics in ``face`` (zeros for travel points).
        normal: (N, 3) float64, unit; zeros for surface points (filled from faces later).
        extrude: (N,) bool.
        path: (N,) int32, local path id, increasing in print order (travel gets its own id).
        piece: (N,) int32, index of the piece (line) the point belongs to, -1 for connector
            and travel points; a segment between two points of one piece lies on its line,
            every other extruding segment is a connector.
    """

    points: NDArray[np.float64]
    face: NDArray[np.int32]
    bary: NDArray[np.float64]
    normal: NDArray[np.float64]
    extrude: NDArray[np.bool_]
    path: NDArray[np.int32]
    piece: NDArray[np.int32]

    def connector_segments(self) -> NDArray[np.bool_]:
        """(N - 1,) bool, depositing segments that join two lines (not on a line)."""
        on_line = (self.piece[1:] == self.piece[:-1]) & (self.piece[1:] >= 0)
        return deposit_mask(self.extrude, self.path) & ~on_line

    @property
    def extrusion_starts(self) -> int:
        """Number of continuous extrusion paths."""
        ids = np.unique(self.path[self.extrude])
        return int(ids.size)


def deposit_mask(extrude: NDArray[np.bool_], path: NDArray[np.integer]) -> NDArray[np.bool_]:
    """(N - 1,) bool: segment i -> i + 1 deposits (both ends extrude, same path id)."""
    return extrude[1:] & extrude[:-1] & (path[1:] == path[:-1])


def link_pieces(
    lines: SurfaceLines,
    pieces: list[Piece],
    vertices: NDArray[np.float64],
    faces: NDArray[np.int32],
    mg: MeshGraph,
    width: NDArray[np.float64],
    lifter: Lifter,
    lift: float,
    extrude_factor: float = EXTRUDE_FACTOR,
    joiner: Joiner | None = None,
    spiral: bool = False,
) -> LinkedPath:
    """Join ``pieces`` (on ``vertices``/``faces``) into paths; see the module rule.

    Args:
        lines: the component's (resampled) lines.
        pieces: print order from ``ordering.order_lines``.
        vertices: (n, 3) float64, mm, layer component vertices.
        faces: (m, 3) int32.
        mg: its edge graph.
        width: (P,) float64, mm, toolpath width at each line point.
        lifter: travel clearance helper for this layer.
        lift: mm, travel clearance above the layer.
        extrude_factor: connectors on the surface up to this times W extrude (default
            ``EXTRUDE_FACTOR``); longer gaps are lifted travel moves (a new start).
        joiner: connectors already computed for these lines (same width and factor), or
            None to compute them here.
        spiral: consecutive joinable closed rings (contours) blend into each other instead
            of a connector stepping across (``spiral.py``).
    """
    if joiner is None:
        joiner = Joiner(lines, vertices, faces, mg, width, lifter, extrude_factor)
    pts: list[NDArray[np.float64]] = []
    fcs: list[NDArray[np.int32]] = []
    brs: list[NDArray[np.float64]] = []
    nrm: list[NDArray[np.float64]] = []
    ext: list[NDArray[np.bool_]] = []
    pid: list[NDArray[np.int32]] = []
    pcs: list[NDArray[np.int32]] = []
    current = -1

    def add(p: NDArray[np.float64], f: NDArray[np.int32], b: NDArray[np.float64],
            n: NDArray[np.float64], e: bool, path: int, piece: int = -1) -> None:
        pcs.append(np.full(len(p), piece, dtype=np.int32))
        pts.append(p)
        fcs.append(f)
        brs.append(b)
        nrm.append(n)
        ext.append(np.full(len(p), e))
        pid.append(np.full(len(p), path, dtype=np.int32))

    if spiral:
        planner = SpiralPlanner(lines, vertices, faces, width, extrude_factor)
        runs = spiral_runs(planner, pieces, joiner.can_join)
    else:
        runs = [Run(p.points, p.line, None, False) for p in pieces]
    prev_end: int | None = None
    into_next = False
    for k, run in enumerate(runs):
        idx = run.points
        first = int(idx[0])
        joined = into_next
        if prev_end is not None and not into_next:
            w = 0.5 * (width[prev_end] + width[first])
            conn = joiner.get(prev_end, first)
            if conn is not None:
                add(conn.points, conn.face, conn.bary, np.zeros_like(conn.points), True, current)
                joined = True
            else:
                current += 1
                tp, tn = lifter.travel(lines.points[prev_end], lines.points[first], lift,
                                       2.0 * w)
                add(tp, np.full(len(tp), -1, np.int32), np.zeros_like(tp), tn, False, current)
        if not joined:
            current += 1
        add(lines.points[idx], lines.face[idx].astype(np.int32), lines.bary[idx],
            np.zeros((len(idx), 3)), True, current, k)
        if run.tail is not None:
            # a blend into the next ring: on the layer, between two lines (piece -1)
            add(run.tail.points, run.tail.face, run.tail.bary, np.zeros_like(run.tail.points),
                True, current)
        prev_end = int(idx[-1])
        into_next = run.into_next
    if not pts:
        return LinkedPath(np.zeros((0, 3)), np.zeros(0, np.int32), np.zeros((0, 3)),
                          np.zeros((0, 3)), np.zeros(0, bool), np.zeros(0, np.int32),
                          np.zeros(0, np.int32))
    return LinkedPath(
        points=np.concatenate(pts),
        face=np.concatenate(fcs).astype(np.int32),
        bary=np.concatenate(brs),
        normal=np.concatenate(nrm),
        extrude=np.concatenate(ext),
        path=np.concatenate(pid).astype(np.int32),
        piece=np.concatenate(pcs).astype(np.int32),
    )
