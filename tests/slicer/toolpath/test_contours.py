"""Boundary-conformal contours (eq. 9) and the iso-line machinery under them."""

from __future__ import annotations

import numpy as np
import pytest

from slicer.errors import InputError
from slicer.toolpath import contours, geodesic, isolines
from tests.slicer.toolpath.pattern_meshes import disc, dome


def _check_on_faces(v: np.ndarray, f: np.ndarray, lines: object) -> None:
    pts, face, bary = lines.points, lines.face, lines.bary  # type: ignore[attr-defined]
    assert np.allclose(bary.sum(axis=1), 1.0)
    assert bary.min() >= -1e-12
    assert np.allclose(np.einsum("ij,ijk->ik", bary, v[f[face]]), pts, atol=1e-9)


def test_annulus_contours_are_concentric_circles_at_the_spacing() -> None:
    v, f = disc(30.0, 0.6, inner=10.0, jitter=0.2)
    d = geodesic.boundary_distance(v, f)
    w = 1.5
    lines = contours.contour_lines(v, f, d, w)
    _check_on_faces(v, f, lines)
    assert lines.closed.all()
    radius = np.array([np.linalg.norm(lines.points[lines.line == i, :2], axis=1).mean()
                       for i in range(lines.n_lines)])
    spread = np.array([np.ptp(np.linalg.norm(lines.points[lines.line == i, :2], axis=1))
                       for i in range(lines.n_lines)])
    # the ridge of d (r = 20) is where the two families meet; look at the lines clear of it
    clear = np.abs(radius - 20.0) > 1.5
    assert spread[clear].max() < 0.15 * w  # circles
    inner = np.sort(radius[clear & (radius < 20.0)])
    outer = np.sort(radius[clear & (radius > 20.0)])
    for side in (inner, outer):
        assert len(side) == 6  # levels 0.75 + 1.5 k < 8.5
        assert np.diff(side) == pytest.approx(np.full(len(side) - 1, w), rel=0.02)
    assert inner[0] == pytest.approx(10.0 + 0.5 * w, abs=0.1)
    assert outer[-1] == pytest.approx(30.0 - 0.5 * w, abs=0.1)


def test_iso_lines_on_a_dome_follow_the_levels_and_are_ordered() -> None:
    v, f = disc(10.0, 0.8)
    v = dome(v, 4.0, 10.0)
    levels = np.array([0.5, 1.7, 3.1])
    lines = isolines.iso_lines(v, f, v[:, 2], levels)
    _check_on_faces(v, f, lines)
    assert lines.n_lines == 3 and lines.closed.all()
    for i, c in enumerate(np.sort(levels)):
        pts = lines.points[lines.line == np.argsort([lines.points[lines.line == k, 2].mean()
                                                     for k in range(3)])[i]]
        assert np.allclose(pts[:, 2], c)
        step = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        assert step.max() < 2.0  # consecutive points are neighbours along the loop


def test_open_lines_end_on_the_boundary() -> None:
    v, f = disc(10.0, 0.8)
    lines = isolines.iso_lines(v, f, v[:, 0], np.array([-3.0, 0.0, 4.0]))
    assert lines.n_lines == 3 and not lines.closed.any()
    starts = np.flatnonzero(np.r_[True, np.diff(lines.line) != 0])
    ends = np.r_[starts[1:] - 1, len(lines.line) - 1]
    for idx in (starts, ends):
        assert np.allclose(np.linalg.norm(lines.points[idx, :2], axis=1), 10.0, atol=0.05)


def test_contour_input_errors() -> None:
    v, f = disc(5.0, 1.0)
    with pytest.raises(InputError):
        contours.contour_lines(v, f, np.zeros(3), 1.0)
    with pytest.raises(InputError):
        contours.contour_lines(v, f, np.zeros(len(v)), 0.0)
    assert contours.contour_lines(v, f, np.zeros(len(v)), 1.0).n_lines == 0
