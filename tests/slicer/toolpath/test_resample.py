"""Resampling lines on a mesh keeps them on the faces at the requested spacing."""

from __future__ import annotations

import numpy as np
import pytest

from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.mapback import interpolate
from slicer.toolpath.resample import (
    drop_short_lines,
    drop_tiny_loops,
    line_lengths,
    resample_lines,
)

from .test_build import disc_mesh


def _dome_contours() -> tuple[np.ndarray, np.ndarray, SurfaceLines]:
    from slicer.toolpath.contours import contour_lines
    from slicer.toolpath.geodesic import boundary_distance

    v, f = disc_mesh(12.0, 1.0)
    v[:, 2] = 4.0 * (1 - (v[:, 0] ** 2 + v[:, 1] ** 2) / 144.0)
    d = boundary_distance(v, f)
    return v, f, contour_lines(v, f, d, 2.0, 1.0)


def _check_on_faces(lines: SurfaceLines, v: np.ndarray, f: np.ndarray) -> None:
    assert np.all(lines.bary >= -1e-12)
    assert np.allclose(lines.bary.sum(axis=1), 1.0)
    assert np.allclose(lines.points, interpolate(v, f, lines.face, lines.bary), atol=1e-9)


def test_resampled_contours_stay_on_faces() -> None:
    v, f, lines = _dome_contours()
    _check_on_faces(lines, v, f)
    step = np.full(len(lines.points), 0.4)
    out = resample_lines(lines, v, f, step)
    _check_on_faces(out, v, f)
    assert out.n_lines == lines.n_lines
    assert np.array_equal(out.closed, lines.closed)
    # length is kept (new points lie on the old polyline) and spacing is about the step
    assert np.allclose(line_lengths(out), line_lengths(lines), rtol=0.01)
    seg = np.linalg.norm(np.diff(out.points, axis=0), axis=1)[out.line[1:] == out.line[:-1]]
    assert 0.3 < seg.min() and seg.max() <= 0.4 + 1e-9
    assert np.median(seg) == pytest.approx(0.4, rel=0.05)


def test_resample_variable_step() -> None:
    v, f, lines = _dome_contours()
    x = lines.points[:, 0]
    step = np.where(x > 0, 0.8, 0.2)
    out = resample_lines(lines, v, f, step)
    seg = np.linalg.norm(np.diff(out.points, axis=0), axis=1)
    same = out.line[1:] == out.line[:-1]
    mid_x = 0.5 * (out.points[1:, 0] + out.points[:-1, 0])
    assert np.median(seg[same & (mid_x > 2)]) > 2.5 * np.median(seg[same & (mid_x < -2)])


def test_resample_inside_one_face_is_exact() -> None:
    v, f = disc_mesh(3.0, 1.0)
    bary = np.array([[0.8, 0.1, 0.1], [0.1, 0.1, 0.8]])
    face = np.array([3, 3], dtype=np.int32)
    pts = interpolate(v, f, face, bary)
    lines = SurfaceLines(pts, face, bary, np.zeros(2, np.int32), np.array([False]))
    length = float(np.linalg.norm(pts[1] - pts[0]))
    out = resample_lines(lines, v, f, np.full(2, length / 4.0))
    assert len(out.points) == 5
    assert np.all(out.face == 3)
    assert np.allclose(out.points, pts[0] + np.linspace(0, 1, 5)[:, None] * (pts[1] - pts[0]))


def test_drop_short_lines() -> None:
    _, _, lines = _dome_contours()
    lengths = line_lengths(lines)
    cut = float(np.median(lengths))
    out = drop_short_lines(lines, cut)
    assert out.n_lines == int(np.sum(lengths >= cut))
    assert np.all(line_lengths(out) >= cut)
    assert np.array_equal(np.unique(out.line), np.arange(out.n_lines))


def test_drop_tiny_loops_keeps_open_lines_and_long_loops() -> None:
    """Contour loops of a dome at 1, 3, 5, ... mm from the rim: with W = 2 mm and factor 2,
    exactly the closed loops shorter than 4 mm go; the rest are kept unchanged."""
    _, _, lines = _dome_contours()
    width = np.full(len(lines.points), 2.0)
    lengths = line_lengths(lines)
    limit = 4.0
    # a loop as short as that is what a local maximum of the distance leaves
    small = lines._replace(points=lines.points * np.where(lines.line == lines.line.max(),
                                                          0.02, 1.0)[:, None])
    small_len = line_lengths(small)
    assert small_len.min() < limit < lengths.min()
    out = drop_tiny_loops(small, width, limit / 2.0)
    assert out.n_lines == int(np.sum(~(small.closed & (small_len < limit))))
    assert np.all(line_lengths(out) >= limit)
    assert drop_tiny_loops(lines, width, 2.0) is lines


def test_trim_open_line_ends() -> None:
    v, f = disc_mesh(6.0, 1.0)
    # an open straight line across the disc: sample it densely inside faces
    from .test_linking import _locate

    x = np.linspace(-5.0, 5.0, 41)
    pts = np.column_stack([x, np.full_like(x, 0.3), np.zeros_like(x)])
    face, bary = _locate(pts, v, f)
    lines = SurfaceLines(interpolate(v, f, face, bary), face, bary,
                         np.zeros(41, np.int32), np.array([False]))
    out = resample_lines(lines, v, f, np.full(41, 0.5), trim=np.array([[1.0, 2.5]]))
    _check_on_faces(out, v, f)
    assert out.points[0, 0] == pytest.approx(-4.0, abs=1e-6)
    assert out.points[-1, 0] == pytest.approx(2.5, abs=1e-6)
    assert line_lengths(out)[0] == pytest.approx(6.5, rel=1e-6)
    # a trim longer than the line removes it
    gone = resample_lines(lines, v, f, np.full(41, 0.5), trim=np.array([[6.0, 5.0]]))
    assert gone.n_lines == 0
