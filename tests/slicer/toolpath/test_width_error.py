"""Measured spacing between toolpath lines and the width-error summary."""

from __future__ import annotations

import numpy as np
import pytest

from slicer.toolpath import width_error


def _parallel(n_lines: int, gap: float, n_pts: int = 50) -> tuple[np.ndarray, np.ndarray]:
    x = np.linspace(0.0, 20.0, n_pts)
    pts = np.concatenate([np.column_stack([x, np.full(n_pts, k * gap), np.zeros(n_pts)])
                          for k in range(n_lines)])
    return pts, np.repeat(np.arange(n_lines), n_pts).astype(np.int32)


def test_parallel_lines_measure_their_gap() -> None:
    pts, line = _parallel(5, 1.3)
    s = width_error.line_spacing(pts, line)
    assert np.allclose(s, 1.3)
    err = width_error.width_error(s, 1.0)
    assert err.p50 == pytest.approx(0.3) and err.p95 == pytest.approx(0.3)


def test_sparse_samples_measure_distance_to_segments() -> None:
    # neighbour sampled every 2 mm with a half-step offset: the segment distance is still exact
    pts, line = _parallel(2, 1.0, n_pts=11)
    pts[line == 1, 0] += 1.0
    s = width_error.line_spacing(pts, line)
    inner = (pts[:, 0] > 1.5) & (pts[:, 0] < 19.5)
    assert np.allclose(s[inner], 1.0)


def test_folded_line_is_its_own_neighbour() -> None:
    # a hairpin: one polyline going out along y = 0 and back along y = 0.8
    x = np.linspace(0.0, 20.0, 81)
    turn = 0.4 * np.array([[np.sin(a), 1.0 - np.cos(a), 0.0] for a in np.linspace(0, np.pi, 9)])
    pts = np.concatenate([np.column_stack([x, 0 * x, 0 * x]), turn[1:-1] + np.array([20.0, 0, 0]),
                          np.column_stack([x[::-1], 0 * x + 0.8, 0 * x])])
    line = np.zeros(len(pts), dtype=np.int32)
    s = width_error.line_spacing(pts, line)
    straight = (pts[:, 0] < 18.0)
    assert np.allclose(s[straight], 0.8)


def test_normals_remove_the_out_of_plane_offset() -> None:
    pts, line = _parallel(2, 1.0)
    pts[line == 1, 2] += 0.5
    normals = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    assert np.allclose(width_error.line_spacing(pts, line, normals=normals), 1.0)
    assert np.allclose(width_error.line_spacing(pts, line), np.hypot(1.0, 0.5))


def test_single_line_has_no_spacing() -> None:
    pts, line = _parallel(1, 1.0)
    s = width_error.line_spacing(pts, line)
    assert np.isnan(s).all()
    assert np.isnan(width_error.width_error(s, 1.0).p50)


def test_closed_loops_measure_across_their_closing_segment() -> None:
    # two concentric squares sampled only at their corners: the measured gap must use the
    # segments, including the one closing each loop
    sq = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    mids = 0.5 * (sq + np.roll(sq, -1, axis=0))
    outer = 3.0 * sq
    pts = np.concatenate([mids, outer])
    line = np.repeat([0, 1], 4).astype(np.int32)
    s = width_error.line_spacing(pts, line, closed=np.array([True, True]))
    assert np.allclose(s[:4], 2.0)  # edge midpoints of the inner square to the outer sides
    open_s = width_error.line_spacing(pts, line, closed=np.array([True, False]))
    assert open_s[3] > 2.0  # without the closing side the nearest outer segment is farther


def test_densely_sampled_lines_still_find_their_neighbour() -> None:
    # 0.02 mm sampling: the 24 nearest samples all lie on the point's own line
    pts, line = _parallel(3, 1.0, n_pts=1001)
    s = width_error.line_spacing(pts, line, k=24)
    assert np.allclose(s, 1.0)


def test_band_width_is_the_sum_of_both_sides() -> None:
    """A 3 mm strip between y = 0 and y = 3 (boundary cut in 0.5 mm segments): the band
    through a point is 3 mm wherever the point sits across it; an annulus 10-14 mm gives
    4 mm (to the polygon's chord error) from a point off its middle."""
    x = np.arange(0.0, 30.0, 0.5)
    lower = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    upper = lower + np.array([0.0, 3.0, 0.0])
    a = np.concatenate([lower[:-1], upper[:-1]])
    b = np.concatenate([lower[1:], upper[1:]])
    pts = np.array([[10.0, 1.0, 0.0], [15.2, 2.5, 0.0], [20.0, 1.5, 0.0]])
    assert np.allclose(width_error.band_width(pts, a, b), 3.0, atol=1e-9)
    t = np.linspace(0.0, 2.0 * np.pi, 200, endpoint=False)
    ring = [r * np.column_stack([np.cos(t), np.sin(t), np.zeros_like(t)]) for r in (10.0, 14.0)]
    a = np.concatenate(ring)
    b = np.concatenate([np.roll(r, -1, axis=0) for r in ring])
    off_middle = 11.2 * np.column_stack([np.cos(t[::7]), np.sin(t[::7]), np.zeros_like(t[::7])])
    assert np.allclose(width_error.band_width(off_middle, a, b), 4.0, atol=0.01)
    # no second side: NaN
    assert np.isnan(width_error.band_width(pts[:1], lower[:-1], lower[1:])).all()


def test_foot_interpolates_the_neighbours_value() -> None:
    # the neighbour sampled every 2 mm, offset half a step: its foot falls between samples
    pts, line = _parallel(2, 1.0, n_pts=11)
    pts[line == 1, 0] += 1.0
    near = width_error.line_neighbours(pts, line)
    value = pts[:, 0] + 10.0 * line  # linear along each line: interpolation is exact
    inner = (line == 0) & (pts[:, 0] > 1.5) & (pts[:, 0] < 19.5)
    assert np.allclose(near.at_foot(value)[inner], pts[inner, 0] + 10.0)
    lone = width_error.line_neighbours(*_parallel(1, 1.0))
    assert np.array_equal(lone.at_foot(np.arange(50.0)), np.arange(50.0))


def test_lines_of_different_width_are_measured_against_their_mean() -> None:
    from slicer.toolpath.lines import SurfaceLines
    from slicer.toolpath.width_measure import measure_width

    # three lines 3, 5 and 7 mm wide, 4 and 6 mm apart: they tile the plane exactly, while
    # each line's nearest neighbour is 1 mm off its own width (the measure before session 13)
    pts, line = _parallel(3, 1.0)
    pts[:, 1] = np.array([0.0, 4.0, 10.0])[line]
    width = np.array([3.0, 5.0, 7.0])[line]
    lines = SurfaceLines(points=pts, line=line, face=np.zeros(len(pts), np.int64),
                         bary=np.tile([1.0, 0.0, 0.0], (len(pts), 1)),
                         closed=np.zeros(3, bool))
    normals = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    measured = measure_width(lines, width, normals, lambda: (np.zeros((0, 3)), np.zeros((0, 3))))
    assert np.allclose(measured.error, 0.0)
    assert np.allclose(np.sort(np.unique(np.round(measured.pointwise, 6))), [1 / 7, 0.2, 1 / 3])
