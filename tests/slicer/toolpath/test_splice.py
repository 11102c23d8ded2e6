"""An open contour printed with the loop beside it (slicer.toolpath.splice)."""

from __future__ import annotations

import itertools

import numpy as np

from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.ordering import Piece, order_lines
from slicer.toolpath.resample import line_index
from slicer.toolpath.splice import find_splices, spliced_points

REACH = 3.0


def _rings(radii: list[float], arcs: list[tuple[float, float, float]]) -> SurfaceLines:
    """Closed circles of the given radii, then open arcs (radius, from deg, to deg), points
    about 0.5 mm apart, in z = 0."""
    pts, line, closed = [], [], []
    for r in radii:
        a = np.linspace(0.0, 2 * np.pi, int(2 * np.pi * r / 0.5), endpoint=False)
        pts.append(np.column_stack([r * np.cos(a), r * np.sin(a), np.zeros_like(a)]))
        closed.append(True)
    for r, a0, a1 in arcs:
        a = np.radians(np.linspace(a0, a1, int(np.radians(a1 - a0) * r / 0.5) + 1))
        pts.append(np.column_stack([r * np.cos(a), r * np.sin(a), np.zeros_like(a)]))
        closed.append(False)
    for i, p in enumerate(pts):
        line.append(np.full(len(p), i, dtype=np.int32))
    p = np.concatenate(pts)
    return SurfaceLines(p, np.zeros(len(p), np.int32), np.full((len(p), 3), 1 / 3),
                        np.concatenate(line), np.array(closed))


def _can_join(lines: SurfaceLines):  # type: ignore[no-untyped-def]
    return lambda a, b: bool(np.linalg.norm(lines.points[a] - lines.points[b]) <= REACH)


def _levels(lines: SurfaceLines) -> np.ndarray:
    r = np.linalg.norm(lines.points[:, :2], axis=1)
    total = np.bincount(lines.line, weights=r)
    return 14.0 - total / np.bincount(lines.line)  # distance from the outer circle


def _starts(lines: SurfaceLines, pieces: list[Piece]) -> int:
    gaps = [np.linalg.norm(lines.points[q.points[0]] - lines.points[p.points[-1]])
            for p, q in itertools.pairwise(pieces)]
    return 1 + int(np.sum(np.array(gaps) > REACH))


def test_open_line_goes_to_the_outer_loop_beside_both_its_ends() -> None:
    lines = _rings([14.0, 12.0, 10.0], [(13.0, 20.0, 80.0)])
    sp = find_splices(lines, line_index(lines), _levels(lines), _can_join(lines))
    assert list(sp) == [0] and sp[0].line == 3
    first = lines.points[line_index(lines).start[3]]
    assert np.linalg.norm(lines.points[sp[0].near_first] - first) < 1.1


def test_spliced_loop_and_open_line_are_one_path_covering_every_point_once() -> None:
    lines = _rings([14.0, 12.0, 10.0], [(13.0, 20.0, 80.0)])
    level = _levels(lines)
    plain = order_lines(lines, np.array([30.0, 0.0, 0.0]), level, 2.0)
    spliced = order_lines(lines, np.array([30.0, 0.0, 0.0]), level, 2.0,
                          can_join=_can_join(lines))
    assert _starts(lines, plain) == 2  # the arc costs a start of its own
    assert _starts(lines, spliced) == 1
    covered = np.concatenate([p.points for p in spliced])
    # every point printed; only the two split points of the loop are shared by its arcs
    assert np.array_equal(np.unique(covered), np.arange(len(lines.points)))
    assert len(covered) == len(lines.points) + 2 + 2  # + the two other loops closing repeats
    loop_runs = [p for p in spliced if p.line == 0]
    assert len(loop_runs) == 2
    beside = min(loop_runs, key=lambda p: len(p.points))
    # the arc printed after the open line is the one beside it (20..80 deg of the circle)
    ang = np.degrees(np.arctan2(lines.points[beside.points, 1], lines.points[beside.points, 0]))
    assert ang.min() > 15.0 and ang.max() < 85.0


def test_entry_is_the_split_point_nearer_the_nozzle() -> None:
    lines = _rings([14.0], [(13.0, 20.0, 80.0)])
    idx = line_index(lines)
    sp = find_splices(lines, idx, _levels(lines), _can_join(lines))[0]
    for pos in (lines.points[sp.near_first], lines.points[sp.near_last]):
        runs, last = spliced_points(lines, idx, sp, pos + np.array([0.0, 0.0, 1.0]))
        assert np.linalg.norm(lines.points[runs[0][0][0]] - pos) < 1e-9
        assert last in (sp.near_first, sp.near_last) and last != runs[0][0][0]


def test_a_loop_hosts_one_open_line_and_far_lines_are_left_alone() -> None:
    lines = _rings([14.0, 12.0], [(13.0, 20.0, 80.0), (13.0, 200.0, 260.0),
                                  (7.0, 0.0, 60.0)])
    sp = find_splices(lines, line_index(lines), _levels(lines), _can_join(lines))
    # both arcs at r = 13 find a loop (one each); the arc at r = 7 is 5 mm from any loop
    assert sorted(s.line for s in sp.values()) == [2, 3]
    assert sorted(sp) == [0, 1]
