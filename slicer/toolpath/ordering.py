"""Print order of the lines of one layer component.

Contours (boundary-conformal loops) are printed outside-in: by increasing distance from the
boundary, so the outer wall that defines the part's shape is laid first and every later loop
is placed against an already printed neighbour; loops at the same level go nearest-neighbour.
(``build`` passes the distance from the outer loop as the level of a band fitted between two
boundaries: outer wall first, then across the band to the inner wall, so that consecutive
lines are neighbours and join.)
A closed loop starts at its point nearest to the nozzle. Stripes are printed as a zig-zag:
greedy nearest neighbour over line ends, each line entered at its nearer end (which flips the
direction of every other stripe on a regular pattern).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.resample import line_index


class Piece(NamedTuple):
    """One line in print order.

    points: (k,) int64, point indices into the SurfaceLines, in print order (a closed loop
        repeats its start point at the end so that it is printed all the way round).
    line: int, the line id.
    """

    points: NDArray[np.int64]
    line: int


def _piece(
    lines: SurfaceLines, start: int, stop: int, line: int, pos: NDArray[np.float64]
) -> tuple[Piece, NDArray[np.float64]]:
    """Best way to enter line ``line`` from ``pos``: returns the piece and its end point."""
    idx = np.arange(start, stop, dtype=np.int64)
    pts = lines.points[start:stop]
    if lines.closed[line]:
        roll = int(np.argmin(np.linalg.norm(pts - pos, axis=1)))
        idx = np.roll(idx, -roll)
        idx = np.append(idx, idx[0])
    elif np.linalg.norm(pts[-1] - pos) < np.linalg.norm(pts[0] - pos):
        idx = idx[::-1]
    return Piece(idx, line), lines.points[idx[-1]]


def _entry_distance(
    lines: SurfaceLines, start: NDArray[np.int64], stop: NDArray[np.int64],
    cand: NDArray[np.int64], pos: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Distance from ``pos`` to the entry of each candidate line (closed: nearest point)."""
    d_first = np.linalg.norm(lines.points[start[cand]] - pos, axis=1)
    d_last = np.linalg.norm(lines.points[stop[cand] - 1] - pos, axis=1)
    out = np.minimum(d_first, d_last)
    for j in np.flatnonzero(lines.closed[cand]):
        c = cand[j]
        out[j] = np.linalg.norm(lines.points[start[c]:stop[c]] - pos, axis=1).min()
    return out


def _order_open(lines: SurfaceLines, start_pos: NDArray[np.float64],
                reach: NDArray[np.float64]) -> list[Piece]:
    """Zig-zag order of lines (stripes) that keeps as many joins short as possible.

    Greedy over line ends with Warnsdorff's rule: from the current end, among the lines whose
    entry lies within ``reach`` (a join that extrudes), take the one whose far end has the
    fewest unvisited lines within reach (so chains are not cut off and stranded), ties by
    distance; with none in reach, travel to the unvisited end with the fewest such
    neighbours, nearest first. The first line is chosen the same way over all lines (a chain
    is best started at one of its ends). Closed lines are entered at their nearest point.
    """
    idx = line_index(lines)
    n = lines.n_lines
    todo = np.flatnonzero(idx.stop > idx.start)
    if todo.size == 0:
        return []
    first, last = idx.start, np.maximum(idx.stop - 1, idx.start)
    ends = np.concatenate([lines.points[first], lines.points[last]])  # end e: line e % n
    radius = np.concatenate([reach[first], reach[last]])
    near = cKDTree(ends).query_ball_point(ends, r=radius)
    unvisited = np.zeros(n, dtype=bool)
    unvisited[todo] = True

    def degree(end: int) -> int:
        own = end % n
        return len({j % n for j in near[end] if j % n != own and unvisited[j % n]})

    pos = np.asarray(start_pos, dtype=np.float64)
    r_now = float(np.median(radius))
    pieces: list[Piece] = []
    while unvisited.any():
        cand = np.flatnonzero(np.r_[unvisited, unvisited])
        dist = np.linalg.norm(ends[cand] - pos, axis=1)
        closed_c = lines.closed[cand % n]
        if np.any(closed_c):
            dist[closed_c] = _entry_distance(lines, idx.start, idx.stop, cand[closed_c] % n,
                                             pos)
        # the first line may start anywhere: where a chain of joinable lines begins
        close = dist <= (r_now if pieces else np.inf)
        pool = np.flatnonzero(close) if np.any(close) else np.arange(len(cand))
        # exit end of each candidate entry (closed lines exit where they enter)
        exits = [int(c) if lines.closed[c % n] else int((c + n) % (2 * n)) for c in cand[pool]]
        deg = np.array([degree(e) for e in exits])
        if not np.any(close):
            deg = np.where(deg == 0, np.iinfo(np.int64).max // 2, deg)  # isolated lines last
        order = np.lexsort((dist[pool], deg))
        pick = int(cand[pool[order[0]]])
        line = pick % n
        unvisited[line] = False
        start, stop = int(idx.start[line]), int(idx.stop[line])
        if lines.closed[line]:
            piece, pos = _piece(lines, start, stop, line, pos)
        else:
            ids = np.arange(start, stop, dtype=np.int64)
            piece = Piece(ids if pick < n else ids[::-1], line)
            pos = lines.points[piece.points[-1]]
        r_now = float(reach[piece.points[-1]])
        pieces.append(piece)
    return pieces


def order_lines(
    lines: SurfaceLines,
    start_pos: NDArray[np.float64],
    level: NDArray[np.float64] | None = None,
    level_step: float = 1.0,
    reach: NDArray[np.float64] | None = None,
) -> list[Piece]:
    """Order all lines; contours by ``level`` (outside-in), then nearest neighbour.

    Args:
        lines: the component's lines (on the original layer).
        start_pos: (3,) float64, mm, the nozzle position before the first line.
        level: (L,) float64, mm, per-line distance from the boundary (contours) or None
            (stripes).
        level_step: mm, levels in the same interval [k, k + 1) * level_step form one ring.
        reach: (P,) float64, mm, per point: the longest join that still extrudes. With it,
            stripes (level None) follow ``_order_open``; without, pure nearest neighbour.

    Returns:
        The pieces in print order.
    """
    if level is None and reach is not None:
        return _order_open(lines, start_pos, reach)
    idx = line_index(lines)
    n = lines.n_lines
    alive = idx.stop > idx.start
    if level is None:
        ring = np.zeros(n, dtype=np.int64)
    else:
        # contour k sits at (k + 1/2) * step: floor keeps rings apart (round would merge
        # 1.5 and 2.5 by rounding half to even)
        ring = np.floor(np.asarray(level) / max(level_step, 1e-9)).astype(np.int64)
    pos = np.asarray(start_pos, dtype=np.float64)
    pieces: list[Piece] = []
    for r in np.unique(ring[alive]):
        todo = np.flatnonzero(alive & (ring == r))
        while todo.size:
            dist = _entry_distance(lines, idx.start, idx.stop, todo, pos)
            k = int(np.argmin(dist))
            line = int(todo[k])
            piece, pos = _piece(lines, int(idx.start[line]), int(idx.stop[line]), line, pos)
            pieces.append(piece)
            todo = np.delete(todo, k)
    return pieces


def line_levels(lines: SurfaceLines, point_value: NDArray[np.float64]) -> NDArray[np.float64]:
    """Mean of a per-point value over each line, (L,) float64."""
    n = lines.n_lines
    count = np.bincount(lines.line, minlength=n)[:n]
    total = np.bincount(lines.line, weights=point_value, minlength=n)[:n]
    return total / np.maximum(count, 1)
