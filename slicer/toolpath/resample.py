"""Resample polylines on a triangle mesh at a width-relative spacing, staying on the mesh.

Each line is cut into equal steps of its width-normalised arc length: the step near a point
is ``spacing * W`` (``ToolpathConfig.waypoint_spacing`` times the local toolpath width). A new
point between two input points a, b is interpolated in barycentric coordinates inside a
triangle that contains both (for iso-lines consecutive points share a triangle: they sit on
two edges of it; the shared one is searched among the two points' faces and their edge
neighbours), so it lies exactly on the layer. If no shared triangle exists (a chord across
several faces) the point is projected onto the nearer endpoint's triangle.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from core.tolerance import tol
from slicer.toolpath.lines import SurfaceLines, empty_lines
from slicer.toolpath.mapback import barycentric, interpolate

# A barycentric coordinate above -BARY_EPS counts as inside the triangle.
BARY_EPS = 1e-6


class LineIndex(NamedTuple):
    """Where each polyline of a SurfaceLines starts and ends.

    start: (L,) int64, index of the first point of each line.
    stop:  (L,) int64, one past the last point.
    """

    start: NDArray[np.int64]
    stop: NDArray[np.int64]


def line_index(lines: SurfaceLines) -> LineIndex:
    """Start/stop of every line id 0..L-1 (lines must be consecutive runs, ids increasing)."""
    n_lines = lines.n_lines
    counts = np.bincount(lines.line, minlength=n_lines)[:n_lines] if len(lines.line) else (
        np.zeros(n_lines, dtype=np.int64)
    )
    stop = np.cumsum(counts).astype(np.int64)
    return LineIndex(start=stop - counts, stop=stop)


def face_neighbours(faces: NDArray[np.int32]) -> NDArray[np.int64]:
    """(m, 3) int64, the face across each edge (corner k -> k + 1), -1 on the boundary."""
    m = len(faces)
    he = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    key = np.sort(he, axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    ks = key[order]
    same = np.all(ks[1:] == ks[:-1], axis=1)
    out = np.full(3 * m, -1, dtype=np.int64)
    i = np.flatnonzero(same)
    out[order[i]] = order[i + 1] // 3
    out[order[i + 1]] = order[i] // 3
    return out.reshape(m, 3)


def common_face(
    pa: NDArray[np.float64], pb: NDArray[np.float64], fa: NDArray[np.int32],
    fb: NDArray[np.int32], vertices: NDArray[np.float64], faces: NDArray[np.int32],
    neighbours: NDArray[np.int64],
) -> tuple[NDArray[np.int32], NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Per segment a triangle holding both ends, and their barycentrics in it.

    Candidates: a's face, b's face and their edge neighbours (an iso-line node on an edge may
    be stored with either adjacent face, so the triangle a segment crosses can be a neighbour
    of both). Returns (face, bary_a, bary_b, ok); ok False: no candidate holds both ends.
    """
    scale = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0))) + 1.0
    cands = np.column_stack([fa, fb, neighbours[fa], neighbours[fb]])  # (S, 8)
    face = fb.astype(np.int32).copy()
    bary_a = np.zeros((len(pa), 3))
    bary_b = np.zeros((len(pa), 3))
    ok = np.zeros(len(pa), dtype=bool)
    for c in range(cands.shape[1]):
        todo = np.flatnonzero(~ok & (cands[:, c] >= 0))
        if todo.size == 0:
            continue
        fc = cands[todo, c].astype(np.int32)
        ba = barycentric(pa[todo], vertices, faces, fc)
        bb = barycentric(pb[todo], vertices, faces, fc)
        good = (ba.min(axis=1) >= -BARY_EPS) & (bb.min(axis=1) >= -BARY_EPS)
        good &= np.linalg.norm(interpolate(vertices, faces, fc, ba) - pa[todo], axis=1) <= (
            tol.on_surface * scale
        )
        good &= np.linalg.norm(interpolate(vertices, faces, fc, bb) - pb[todo], axis=1) <= (
            tol.on_surface * scale
        )
        hit = todo[good]
        face[hit] = fc[good]
        bary_a[hit] = ba[good]
        bary_b[hit] = bb[good]
        ok[hit] = True
    return face, bary_a, bary_b, ok


def resample_lines(
    lines: SurfaceLines,
    vertices: NDArray[np.float64],
    faces: NDArray[np.int32],
    step: NDArray[np.float64],
    min_points: int = 2,
    neighbours: NDArray[np.int64] | None = None,
    trim: NDArray[np.float64] | None = None,
) -> SurfaceLines:
    """Resample every line at (approximately, equalised per line) the local ``step``.

    Args:
        lines: polylines on the mesh (points consistent with face/bary on ``vertices``).
        vertices: (n, 3) float64, mm, the mesh the points lie on.
        faces: (m, 3) int32.
        step: (P,) float64, mm, wanted distance between waypoints near each input point.
        min_points: lines shorter than this many output points are kept with this many
            (open) or 3 (closed).
        neighbours: (m, 3) int64 from ``face_neighbours(faces)`` (computed if None).
        trim: (L, 2) float64, mm, arc length cut off the start and the end of each open line
            (closed lines are not trimmed); a line shorter than its trim is dropped.

    Returns:
        New SurfaceLines on the same mesh; lines of zero length are dropped, ids renumbered.
    """
    if len(lines.points) == 0:
        return empty_lines()
    idx = line_index(lines)
    closed = lines.closed
    nonempty = idx.stop > idx.start
    # Augmented point order: a closed line repeats its first point at the end.
    cl = np.flatnonzero(closed & nonempty)
    aug = np.insert(np.arange(len(lines.points)), idx.stop[cl], idx.start[cl])
    aug_line = lines.line[aug]
    same = aug_line[1:] == aug_line[:-1]
    pts = lines.points[aug]
    seg_len = np.linalg.norm(pts[1:] - pts[:-1], axis=1)
    st = np.maximum(step[aug], tol.zero)
    weight = np.where(same, seg_len / (0.5 * (st[1:] + st[:-1])), 1.0)
    cs = np.concatenate([[0.0], np.cumsum(weight)])
    # First/last augmented position of every line.
    first = np.flatnonzero(np.r_[True, ~same])
    last = np.r_[first[1:] - 1, len(aug) - 1]
    ids = aug_line[first]
    is_closed = closed[ids]
    t_start, t_end = cs[first], cs[last]
    if trim is not None:
        # physical arc length (with a unit gap between lines to keep it increasing)
        phys = np.concatenate([[0.0], np.cumsum(np.where(same, seg_len, 1.0))])
        cut = np.where(is_closed[:, None], 0.0, np.maximum(trim[ids], 0.0))
        p0, p1 = phys[first] + cut[:, 0], phys[last] - cut[:, 1]
        ok_len = p1 > p0 + tol.merge
        t_start = np.where(ok_len, np.interp(p0, phys, cs), t_start)
        t_end = np.where(ok_len, np.interp(p1, phys, cs), t_start)
    total = t_end - t_start
    keep = total > tol.zero
    first, last, ids, total, is_closed, t_start = (
        first[keep], last[keep], ids[keep], total[keep], is_closed[keep], t_start[keep]
    )
    n_int = np.maximum(np.ceil(total - tol.slack).astype(np.int64), 1)
    n_int = np.where(is_closed, np.maximum(n_int, 3), np.maximum(n_int, min_points - 1))
    n_samples = np.where(is_closed, n_int, n_int + 1)
    out_line = np.repeat(np.arange(len(ids)), n_samples)
    offs = np.concatenate([[0], np.cumsum(n_samples)[:-1]])
    k = np.arange(out_line.size) - offs[out_line]
    t = t_start[out_line] + total[out_line] * k / n_int[out_line]
    seg = np.searchsorted(cs, t, side="right") - 1
    seg = np.clip(seg, first[out_line], np.maximum(last[out_line] - 1, first[out_line]))
    denom = cs[seg + 1] - cs[seg]
    frac = np.clip(np.where(denom > tol.zero, (t - cs[seg]) / np.where(denom > 0, denom, 1), 0),
                   0.0, 1.0)
    a, b = aug[seg], aug[np.minimum(seg + 1, len(aug) - 1)]
    if neighbours is None:
        neighbours = face_neighbours(faces)
    face, bary_a, bary_b, ok = common_face(
        lines.points[a], lines.points[b], lines.face[a], lines.face[b], vertices, faces,
        neighbours,
    )
    bary = (1.0 - frac)[:, None] * bary_a + frac[:, None] * bary_b
    if not np.all(ok):
        # Chord across several faces: project onto the nearer end's triangle.
        bad = ~ok
        pos = (1.0 - frac[bad])[:, None] * lines.points[a[bad]] + frac[bad][:, None] * (
            lines.points[b[bad]]
        )
        fb = np.where(frac[bad] < 0.5, lines.face[a[bad]], lines.face[b[bad]]).astype(np.int32)
        face[bad] = fb
        bary[bad] = barycentric(pos, vertices, faces, fb)
    bary = np.clip(bary, 0.0, None)
    bary /= np.maximum(bary.sum(axis=1, keepdims=True), tol.zero)
    points = interpolate(vertices, faces, face, bary)
    return SurfaceLines(
        points=points,
        face=face,
        bary=bary,
        line=out_line.astype(np.int32),
        closed=is_closed.astype(bool),
    )


def line_lengths(lines: SurfaceLines) -> NDArray[np.float64]:
    """(L,) float64, mm, length of each line (a closed line includes its closing segment)."""
    n = lines.n_lines
    if len(lines.points) == 0:
        return np.zeros(n)
    idx = line_index(lines)
    seg = np.linalg.norm(np.diff(lines.points, axis=0), axis=1)
    same = lines.line[1:] == lines.line[:-1]
    total = np.asarray(
        np.bincount(lines.line[1:][same], weights=seg[same], minlength=n)[:n], dtype=np.float64
    )
    ok = idx.stop > idx.start
    close = np.zeros(n)
    close[ok] = np.linalg.norm(
        lines.points[idx.stop[ok] - 1] - lines.points[idx.start[ok]], axis=1
    )
    return total + np.where(lines.closed, close, 0.0)


def select_lines(lines: SurfaceLines, keep: NDArray[np.bool_]) -> SurfaceLines:
    """The lines with ``keep[line]`` True, renumbered 0..L'-1 in their order."""
    new_id = np.cumsum(keep) - 1
    mask = keep[lines.line]
    return SurfaceLines(
        points=lines.points[mask],
        face=lines.face[mask],
        bary=lines.bary[mask],
        line=new_id[lines.line[mask]].astype(np.int32),
        closed=lines.closed[keep],
    )


def drop_short_lines(lines: SurfaceLines, min_length: float) -> SurfaceLines:
    """Lines at least ``min_length`` mm long (and with at least two points)."""
    if lines.n_lines == 0:
        return lines
    idx = line_index(lines)
    keep = (line_lengths(lines) >= min_length) & (idx.stop - idx.start >= 2)
    return select_lines(lines, keep)


def drop_tiny_loops(lines: SurfaceLines, width: NDArray[np.float64], factor: float
                    ) -> SurfaceLines:
    """Lines without the closed loops shorter than ``factor`` x their mean width.

    width: (P,) float64, mm, the toolpath width at each point. A loop that short (around a
    local maximum of the boundary distance) encloses less than a filament's width: printed,
    it is one blob, not a loop.
    """
    if not lines.closed.any():
        return lines
    n = lines.n_lines
    w_line = (np.bincount(lines.line, weights=width, minlength=n)[:n]
              / np.maximum(np.bincount(lines.line, minlength=n)[:n], 1))
    tiny = lines.closed & (line_lengths(lines) < factor * w_line)
    return select_lines(lines, ~tiny) if tiny.any() else lines

