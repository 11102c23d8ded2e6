"""Joins of stripe ends whose connector would cross another line."""

from __future__ import annotations

from itertools import pairwise

import numpy as np

from slicer.toolpath.join_crossing import JoinCrossing
from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.ordering import Piece, order_lines


def _lines(segments: list[tuple[tuple[float, float], tuple[float, float]]], step: float = 0.3
           ) -> SurfaceLines:
    """Straight lines from a to b in z = 0, points ``step`` mm apart (face/bary unused)."""
    pts, ids = [], []
    for k, (a, b) in enumerate(segments):
        n = max(int(np.ceil(np.hypot(b[0] - a[0], b[1] - a[1]) / step)), 1) + 1
        t = np.linspace(0.0, 1.0, n)[:, None]
        xy = (1 - t) * np.array(a) + t * np.array(b)
        pts.append(np.column_stack([xy, np.zeros(n)]))
        ids.append(np.full(n, k))
    p = np.concatenate(pts)
    return SurfaceLines(points=p, face=np.zeros(len(p), np.int32),
                        bary=np.tile([1.0, 0.0, 0.0], (len(p), 1)),
                        line=np.concatenate(ids).astype(np.int32),
                        closed=np.zeros(len(segments), bool))


def test_a_chord_over_a_third_line_crosses_it() -> None:
    # three stripes 2 mm apart along x; the middle one runs on past the others' right ends
    lines = _lines([((0, 0), (10, 0)), ((0, 2), (14, 2)), ((0, 4), (10, 4))])
    test = JoinCrossing(lines, 2.0)
    end = [int(np.flatnonzero(lines.line == k)[-1]) for k in range(3)]
    start = [int(np.flatnonzero(lines.line == k)[0]) for k in range(3)]
    assert test.crosses(end[0], end[2])  # over the middle stripe
    assert not test.crosses(start[0], start[1])  # neighbours: a U-turn beside no other line
    assert not test.crosses(end[1], start[1])  # a line's own points are not another line


def test_the_path_cover_leaves_crossing_joins_out() -> None:
    # the two outer stripes' right ends are 4 mm apart (within a 6 mm join), but the middle
    # stripe runs on between them; its right end reaches the top stripe's without crossing
    lines = _lines([((0, 0), (10, 0)), ((0, 2), (14, 2)), ((2, 4), (10, 4))])
    reach = np.full(len(lines.points), 6.0)
    start = np.array([-1.0, 0.0, 0.0])
    right = {int(np.flatnonzero(lines.line == k)[-1]) for k in (0, 2)}

    def across(pieces: list[Piece]) -> bool:
        """Two consecutive pieces that meet at the outer stripes' right ends."""
        return any({int(a.points[-1]), int(b.points[0])} == right
                   for a, b in pairwise(pieces))

    blind = order_lines(lines, start, None, 1e-6, reach)  # a spacing too small to see lines
    vetoed = order_lines(lines, start, None, 2.0, reach)
    assert across(blind)
    assert not across(vetoed)
    assert sorted(p.line for p in vetoed) == [0, 1, 2]
