"""Boundary-conformal contours (eq. 9) and the iso-line machinery under them."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import InputError
from slicer.toolpath import contours, geodesic, isolines
from tests.slicer.toolpath.pattern_meshes import disc, dome, eccentric_annulus


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


def _sides(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    from slicer.toolpath.surface import boundary_loops

    loops = boundary_loops(f)
    length = [np.linalg.norm(v[lp] - v[np.roll(lp, 1)], axis=1).sum() for lp in loops]
    outer = int(np.argmax(length))
    inner = np.concatenate([lp for i, lp in enumerate(loops) if i != outer])
    return geodesic.distance_from(v, f, loops[outer]), geodesic.distance_from(v, f, inner)


def test_distance_from_one_loop_of_an_annulus() -> None:
    v, f = disc(20.0, 0.6, inner=10.0, jitter=0.2)
    d_out, d_in = _sides(v, f)
    r = np.linalg.norm(v[:, :2], axis=1)
    assert np.abs(d_out - (20.0 - r)).max() < 0.2
    assert np.abs(d_in - (r - 10.0)).max() < 0.2
    with pytest.raises(InputError):
        geodesic.distance_from(v, f, np.array([-5]))


@pytest.mark.parametrize(("w", "radii"), [(2.3, [11.25, 13.75, 16.25, 18.75]),
                                          (1.9, [11.0, 13.0, 15.0, 17.0, 19.0])])
def test_two_sided_contours_fit_a_whole_number_of_circles(w: float, radii: list[float]) -> None:
    # a 10 mm band holds round(10 / w) circles at the even pitch 10 / n, the outer ones half
    # a pitch inside their boundary (eq. 9 would leave a 0.8 mm gap at w = 2.3 mm)
    v, f = disc(20.0, 0.6, inner=10.0, jitter=0.2)
    lines = contours.two_sided_contour_lines(v, f, *_sides(v, f), w)
    _check_on_faces(v, f, lines)
    assert lines.closed.all()
    rad = [np.linalg.norm(lines.points[lines.line == i, :2], axis=1)
           for i in range(lines.n_lines)]
    assert max(float(np.ptp(r)) for r in rad) < 0.1
    assert np.sort([r.mean() for r in rad]) == pytest.approx(radii, abs=0.05)


def test_two_sided_contours_branch_where_the_band_widens() -> None:
    from slicer.toolpath.surface_geometry import SurfaceGeometry
    from slicer.toolpath.width_error import line_spacing

    v, f = eccentric_annulus()
    w = 2.45
    lines = contours.two_sided_contour_lines(v, f, *_sides(v, f), w,
                                             SurfaceGeometry(v, f).smoother(2.0 * w))
    _check_on_faces(v, f, lines)
    # the band is 10 mm wide at +x and 18 mm at -x: b / w = 4.1 and 7.3, 4 and 7 lines
    p = lines.points[:, :2]
    for direction, band, count in ((1.0, 10.0, 4), (-1.0, 18.0, 7)):
        along = direction * p[:, 0]
        on_ray = np.abs(p[:, 1]) < 0.3
        hits = np.sort(along[on_ray & (along > 0)])
        crossings = hits[np.r_[True, np.diff(hits) > 0.5]]
        assert len(crossings) == count
        # (the pitch is blended with the wider band around: within 10 %)
        assert np.diff(crossings) == pytest.approx(np.full(count - 1, band / count), rel=0.1)
    spacing = line_spacing(lines.points, lines.line, closed=lines.closed)
    err = np.abs(spacing - w) / w
    assert np.percentile(err, 90) < 0.1
    # eq. 9 on the same band: the families meet with gaps and overlaps along the medial line
    eq9 = contours.contour_lines(v, f, geodesic.boundary_distance(v, f), w)
    err9 = np.abs(line_spacing(eq9.points, eq9.line, closed=eq9.closed) - w) / w
    assert np.percentile(err, 90) < np.percentile(err9, 90)
    assert np.percentile(err, 95) < 0.5 * np.percentile(err9, 95)


def test_band_pitch_is_the_band_over_a_whole_count() -> None:
    # 10 mm at 2.3 mm: round(4.35) = 4 lines, 2.5 mm apart; 11.8 mm: 5 lines, 2.36 mm
    pitch, band = contours.band_pitch(np.array([4.0, 5.0]), np.array([6.0, 6.8]), 2.3)
    assert band == pytest.approx([10.0, 11.8])
    assert pitch == pytest.approx([2.5, 2.36])


@pytest.mark.parametrize("eccentric", [False, True])
def test_band_pitch_predicts_the_spacing_of_the_fitted_lines(eccentric: bool) -> None:
    # a 10 mm annulus at w = 2.3 mm: 4 circles 2.5 mm apart, 8.7 % off w everywhere and on
    # the pitch; an eccentric band (10 to 18 mm) changes its count and the blended pitch
    # follows the lines there too, never worse than w
    from slicer.toolpath.mapback import interpolate
    from slicer.toolpath.surface_geometry import PITCH_SMOOTHING, SurfaceGeometry
    from slicer.toolpath.width_error import line_spacing

    v, f = eccentric_annulus() if eccentric else disc(20.0, 0.6, inner=10.0, jitter=0.2)
    w = 2.1 if eccentric else 2.3
    smooth = SurfaceGeometry(v, f).smoother(PITCH_SMOOTHING * w)
    lines = contours.two_sided_contour_lines(v, f, *_sides(v, f), w, smooth)
    pitch, _ = contours.band_pitch(*_sides(v, f), w, smooth)
    spacing = line_spacing(lines.points, lines.line, closed=lines.closed)
    at = interpolate(pitch, f, lines.face, lines.bary)
    err_pitch = np.percentile(np.abs(spacing - at) / at, [50, 90])
    err_w = np.percentile(np.abs(spacing - w) / w, [50, 90])
    if eccentric:
        assert err_pitch[1] < 0.06
        assert np.all(err_pitch < 0.8 * err_w)
    else:
        assert at == pytest.approx(2.5, rel=0.01)
        assert err_pitch[1] < 0.02
        assert err_w[0] == pytest.approx(0.087, abs=0.01)


def test_two_sided_contour_input_errors() -> None:
    v, f = disc(20.0, 0.6, inner=10.0)
    d_out, d_in = _sides(v, f)
    with pytest.raises(InputError):
        contours.two_sided_contour_lines(v, f, d_out[:3], d_in, 1.0)
    with pytest.raises(InputError):
        contours.two_sided_contour_lines(v, f, d_out, d_in, 0.0)
    assert contours.band_count(np.array([0.2, 4.4, 4.6]), 1.0).tolist() == [1, 4, 5]
