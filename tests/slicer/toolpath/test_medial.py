"""The medial line of a narrow strip and the strip's width across it."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import Delaunay

from slicer.toolpath.medial import medial_lines, strip_width
from tests.slicer.toolpath.pattern_meshes import flat_mesh


def strip(length: float, width: float, h: float, seed: int = 0
          ) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
    """A flat rectangle length x width (mm) in z = 0, edges about h, interior jittered."""
    rng = np.random.default_rng(seed)
    xs = np.linspace(0.0, length, round(length / h) + 1)
    ys = np.linspace(0.0, width, max(round(width / h), 1) + 1)
    x, y = np.meshgrid(xs, ys)
    p = np.column_stack([x.ravel(), y.ravel()])
    inner = (p[:, 0] > 0) & (p[:, 0] < length) & (p[:, 1] > 0) & (p[:, 1] < width)
    p[inner] += 0.2 * h * rng.uniform(-1, 1, (int(inner.sum()), 2))
    return flat_mesh(p, Delaunay(p).simplices)


def wedge(length: float, half_angle_deg: float, h: float
          ) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
    """A flat isosceles wedge, tip at the origin, opening along +x to ``length`` (mm)."""
    pts = []
    for x in np.arange(0.0, length + 0.5 * h, h):
        half = x * np.tan(np.radians(half_angle_deg))
        pts.append(np.column_stack([np.full(max(int(np.ceil(2 * half / h)), 1) + 1, x),
                                    np.linspace(-half, half,
                                                max(int(np.ceil(2 * half / h)), 1) + 1)]))
    p = np.unique(np.concatenate(pts).round(9), axis=0)
    return flat_mesh(p, Delaunay(p).simplices)


def test_a_strip_holds_one_line_along_its_middle_from_end_to_end() -> None:
    v, f = strip(30.0, 3.0, 0.4)
    lines = medial_lines(v, f)
    assert lines.n_lines == 1 and not lines.closed[0]
    assert np.abs(lines.points[:, 1] - 1.5).max() < 0.1
    # carried on to both square ends (the medial axis alone stops 1.5 mm short of them)
    assert lines.points[:, 0].min() < 0.2 and lines.points[:, 0].max() > 29.8
    width = strip_width(v, f, lines)
    assert np.allclose(width, 3.0, rtol=0.03)


def test_a_strip_one_triangle_wide_still_has_its_middle_line() -> None:
    # every vertex on the boundary: the sides are told apart by their outward normals
    v, f = strip(20.0, 0.5, 0.5)
    lines = medial_lines(v, f)
    assert lines.n_lines == 1
    assert np.abs(lines.points[:, 1] - 0.25).max() < 0.05
    assert np.ptp(lines.points[:, 0]) > 19.0


def test_a_sharp_wedge_has_its_line_along_the_bisector_into_the_tip() -> None:
    v, f = wedge(20.0, 8.0, 0.25)
    lines = medial_lines(v, f)
    assert lines.n_lines == 1
    assert np.abs(lines.points[:, 1]).max() < 0.05
    assert lines.points[:, 0].min() < 2.0 and lines.points[:, 0].max() > 19.0
    width = strip_width(v, f, lines)
    inside = (v[:, 0] > 2.0) & (v[:, 0] < 18.0)
    expected = 2.0 * v[inside, 0] * np.tan(np.radians(8.0))
    assert np.allclose(width[inside], expected, rtol=0.1, atol=0.1)

