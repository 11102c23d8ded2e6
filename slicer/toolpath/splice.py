"""Print a short open contour together with the closed loop beside it, in one extrusion path.

Where a band between two boundaries widens past a whole number of lines, the fitted contours
(``contours.two_sided_contour_lines``) add a short open line between two closed loops. Printed
as a line of its own it costs an extrusion start: the loop is printed all the way round, so
the nozzle comes back to where the loop began, generally far from the open line.

Spliced, loop C and open line O (ends o1, o2 next to loop points P1, P2, both within an
extruding join) form one path: from P2 along the arc of C that does not run beside O to P1,
across to o1, along O to o2, across to P2, and along the arc beside O back to P1. Every arc of
the loop is printed once, the two joins are the short steps the linking would lay anyway,
and the path ends at P1. (P1 and P2 are the two odd-degree nodes of the graph of the loop's
two arcs, the open line and its two joins: an Euler path exists and must run from one to the
other; a loop can host one open line this way.) Measured on the socket: its wall layers,
which have two such lines per band, went from 3 extrusion starts per component to 2.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.resample import LineIndex

NEAREST = 8  # loop points considered around each end of an open line


class Splice(NamedTuple):
    """An open line printed with the closed loop beside it.

    loop: int, id of the closed line.
    line: int, id of the open line.
    near_first: int, point of the loop next to the open line's first point.
    near_last: int, point of the loop next to the open line's last point.
    """

    loop: int
    line: int
    near_first: int
    near_last: int


def find_splices(lines: SurfaceLines, idx: LineIndex, level: NDArray[np.float64],
                 can_join: Callable[[int, int], bool]) -> dict[int, Splice]:
    """Pair open lines with a closed loop both their ends can join; {loop id: Splice}.

    Each loop hosts at most one open line; an open line goes to the loop of lowest ``level``
    (printed first) among those beside both its ends, shortest joins first.
    """
    alive = idx.stop > idx.start
    closed = np.flatnonzero(alive & lines.closed[: lines.n_lines])
    opened = np.flatnonzero(alive & ~lines.closed[: lines.n_lines])
    if closed.size == 0 or opened.size == 0:
        return {}
    loop_pts = np.concatenate([np.arange(idx.start[c], idx.stop[c]) for c in closed])
    tree = cKDTree(lines.points[loop_pts])
    k = min(NEAREST, len(loop_pts))
    options: list[tuple[float, float, int, int, int, int]] = []
    for o in opened.tolist():  # loop over the few open lines of a component
        ends = np.array([idx.start[o], idx.stop[o] - 1])
        dist, near = tree.query(lines.points[ends], k=k)
        dist, near = np.atleast_2d(dist), np.atleast_2d(near)
        owner = lines.line[loop_pts[near]]
        for c in np.intersect1d(owner[0], owner[1]).tolist():
            j0 = int(np.argmax(owner[0] == c))  # nearest point of loop c to each end
            j1 = int(np.argmax(owner[1] == c))
            p0, p1 = int(loop_pts[near[0, j0]]), int(loop_pts[near[1, j1]])
            if p0 == p1 or not (can_join(p0, int(ends[0])) and can_join(int(ends[1]), p1)):
                continue
            options.append((float(level[c]), float(dist[0, j0] + dist[1, j1]), c, o, p0, p1))
    out: dict[int, Splice] = {}
    used: set[int] = set()
    for _, _, c, o, p0, p1 in sorted(options):
        if c in out or o in used:
            continue
        out[c] = Splice(loop=c, line=o, near_first=p0, near_last=p1)
        used.add(o)
    return out


def _arc(start: int, stop: int, first: int, last: int, step: int) -> NDArray[np.int64]:
    """Point indices of a closed loop (points first..last) from ``start`` to ``stop``
    inclusive, walking in direction ``step`` (+1 or -1) and wrapping around."""
    n = last - first + 1
    count = ((stop - start) * step) % n + 1
    return first + (start - first + step * np.arange(count, dtype=np.int64)) % n


def spliced_points(lines: SurfaceLines, idx: LineIndex, splice: Splice,
                   pos: NDArray[np.float64]) -> tuple[list[tuple[NDArray[np.int64], int]], int]:
    """The loop and its open line as three runs of point indices, entered from ``pos``.

    Returns ([(points, line id), ...] in print order: the loop's far arc, the open line, the
    loop's arc beside it) and the last point.
    """
    loop, line = splice.loop, splice.line
    first, last = int(idx.start[loop]), int(idx.stop[loop]) - 1
    ends = (int(idx.start[line]), int(idx.stop[line]) - 1)
    # enter where the nozzle is nearer: P2 is the entry, the open line is walked from its end
    # beside P1 to its end beside P2
    pa, pb = splice.near_first, splice.near_last
    if np.linalg.norm(lines.points[pa] - pos) < np.linalg.norm(lines.points[pb] - pos):
        p2, p1, o1, o2 = pa, pb, ends[1], ends[0]
    else:
        p2, p1, o1, o2 = pb, pa, ends[0], ends[1]
    arcs = [_arc(p2, p1, first, last, +1), _arc(p2, p1, first, last, -1)]
    length = [float(np.linalg.norm(np.diff(lines.points[a], axis=0), axis=1).sum())
              for a in arcs]
    beside, far = (arcs[0], arcs[1]) if length[0] <= length[1] else (arcs[1], arcs[0])
    step = 1 if o2 >= o1 else -1
    open_run = np.arange(o1, o2 + step, step, dtype=np.int64)
    return [(far, loop), (open_run, line), (beside, loop)], p1
