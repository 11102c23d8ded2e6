"""Contours fitted to the local width: the width across a bar and a disc, and a bar whose
width is no whole number of spacings printed without the gap and the doubled ring eq. 9
leaves where its fronts meet."""

from __future__ import annotations

import numpy as np
import pytest

from core.stages import Layers, Pattern
from slicer.config import JobConfig
from slicer.extrusion import load_profile
from slicer.toolpath import ridge_fit
from slicer.toolpath.build import compute_toolpath
from slicer.toolpath.coverage import layer_coverage
from slicer.toolpath.geodesic import boundary_distance
from slicer.toolpath.line_source import LineSource
from slicer.toolpath.ridge_fit import band_across, ridge_fitted_lines
from slicer.toolpath.surface_geometry import SurfaceGeometry
from slicer.toolpath.width_error import line_spacing
from tests.slicer.toolpath.pattern_meshes import disc, plate_with_holes
from tests.slicer.toolpath.test_medial import strip

PROFILE = load_profile("ecoflex-0030")


def test_the_width_across_a_bar_and_a_disc() -> None:
    """Across a bar its width (also in its corners: the ray runs along the other side),
    on a disc its diameter."""
    v, f = strip(30.0, 6.2, 0.4)
    b = band_across(v, f, boundary_distance(v, f, backend="eikonal"))
    middle = (v[:, 0] > 4.0) & (v[:, 0] < 26.0)
    assert np.allclose(b[middle], 6.2, rtol=0.03)
    corner = (v[:, 0] < 1.5) & (v[:, 1] < 0.5 * v[:, 0])
    assert np.allclose(b[corner], 6.2, rtol=0.05)
    v, f = disc(10.0, 0.5)
    b = band_across(v, f, boundary_distance(v, f, backend="eikonal"))
    assert np.median(b) == pytest.approx(20.0, rel=0.03)


def test_a_bar_holds_a_whole_number_of_lines_at_an_even_pitch() -> None:
    """A bar 3.1 spacings wide: eq. 9 lays lines at 0.5 and 1.5 spacings from each side,
    0.1 spacing apart in the middle; fitted, three lines (a ring and the middle line) at
    3.1 / 3 apart."""
    v, f = strip(30.0, 6.2, 0.4)
    d = boundary_distance(v, f, backend="eikonal")
    lines, pitch = ridge_fitted_lines(v, f, d, band_across(v, f, d), 2.0)
    spacing = line_spacing(lines.points, lines.line)
    mid = (lines.points[:, 0] > 5.0) & (lines.points[:, 0] < 25.0)
    assert np.allclose(spacing[mid], 6.2 / 3, rtol=0.04)
    assert np.median(pitch) == pytest.approx(6.2 / 3, rel=0.02)


def _contour_layer(v: np.ndarray, f: np.ndarray, fit: bool) -> tuple[float, float, float, float]:
    """Gap, overlap, contour width error p90 and volume error of one flat contour layer
    (H 0.6 mm, W 2.3 mm) with ``toolpath.fit_ridge`` = ``fit``; printed in one path (the
    ring joined to the middle line that follows it)."""
    layers = Layers(v, f, np.zeros(len(f), np.int32), np.full(len(v), 0.6),
                    np.tile([0.0, 0.0, 1.0], (len(v), 1)))
    job = JobConfig().with_overrides(toolpath={"fit_ridge": fit})
    res = compute_toolpath(layers, job, PROFILE, measure_baselines=False, workers=1)
    assert np.all(res.toolpath.pattern[res.toolpath.extrude] == Pattern.CONTOUR)
    cov = layer_coverage(layers, res.toolpath, max_samples=20_000)
    assert res.report["extrusion_starts"]["total"] == 1
    p90 = float(res.report["width_error"]["contour"]["p90"])
    return float(cov.gap[0]), float(cov.overlap[0]), p90, float(res.report["layer_volume_error"])


def test_fronts_meet_without_a_gap_or_a_doubled_line() -> None:
    """A bar 2.7 W wide (a neck of a machined part): eq. 9's second ring lies 0.2 W from
    its other side (doubled; width error p90 200 %). Fitted to the width, a ring and the
    middle line at 2.7 / 3 W: the contour targets hold (width error p90 <= 10 %, gap and
    overlap <= 3 % each) with the volume."""
    v, f = strip(40.0, 6.3, 0.5)
    gap0, overlap0, p90_0, _ = _contour_layer(v, f, False)
    gap, overlap, p90, volume = _contour_layer(v, f, True)
    assert p90 < p90_0 and gap + overlap < gap0 + overlap0
    assert p90 <= 0.10
    assert gap <= 0.03 and overlap <= 0.03
    assert abs(volume) <= 0.01


def ellipse(a: float, b: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Flat ellipse with semi-axes a, b (mm) in z = 0, edge length about h."""
    from scipy.spatial import Delaunay

    from tests.slicer.toolpath.pattern_meshes import flat_mesh

    ys = np.arange(-b, b + h, h * np.sqrt(3) / 2)
    p = np.concatenate([np.column_stack([np.arange(-a, a + h, h) + (0.5 * h if i % 2 else 0.0),
                                         np.full(int(np.ceil((2 * a + h) / h)), y)])
                        for i, y in enumerate(ys)])
    p = p[(p[:, 0] / (a - 0.5 * h)) ** 2 + (p[:, 1] / (b - 0.5 * h)) ** 2 < 1.0]
    t = np.linspace(0.0, 2.0 * np.pi, int(np.ceil(np.pi * (a + b) / h)), endpoint=False)
    p = np.concatenate([p, np.column_stack([a * np.cos(t), b * np.sin(t)])])
    return flat_mesh(p, Delaunay(p).simplices)


def test_an_ellipse_whose_ends_drop_a_line_gets_the_pitch_of_the_lines_laid() -> None:
    """An ellipse 3.6 W wide (a cross-section of a knotted tube): round(3.6) = 4 lines
    across its middle, but its narrower ends blend the count down and the room a line
    needs keeps 3 (a ring and the middle line). Laid at the blended 4-line pitch, those 3
    stand too far apart and print too narrow for it: a bare strip along each side of the
    middle line (gap 10.7 %, width error p90 34 %). At the pitch of the 3 laid the strip
    is covered (gap 5.0 %, overlap 5.8 %, p90 20 %, volume kept). Not the contour targets
    yet: the width read across the ellipse's flanks (rays along its normals cut it
    obliquely) is too wide, which clips the middle line short of the ends."""
    v, f = ellipse(14.0, 4.15, 0.5)
    gap, overlap, p90, volume = _contour_layer(v, f, True)
    assert gap <= 0.07 and overlap <= 0.07
    assert p90 <= 0.25
    assert abs(volume) <= 0.01


def test_a_plate_with_holes_keeps_the_pitch_that_spaces_its_lines_better(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A plate with two large holes (no band: the families from its rim and from the
    holes meet in between). There the pitch of the lines laid where one is dropped for
    room (``_laid_pitch``) spaces them worse than the blended pitch (width error p90 75 %
    against 70 %; a machined plate with five holes: 45 % against 32 %), as it spaces an
    ellipse's better: the component gets the blended pitch where that keeps its spacing
    better in the tail and on average (p90 and mean)."""
    v, f = plate_with_holes()
    layers = Layers(v, f, np.zeros(len(f), np.int32), np.full(len(v), 0.6),
                    np.tile([0.0, 0.0, 1.0], (len(v), 1)))
    job = JobConfig().with_overrides(toolpath={"fit_ridge": True})

    def p90() -> float:
        res = compute_toolpath(layers, job, PROFILE, measure_baselines=False, workers=1)
        return float(res.report["width_error"]["contour"]["p90"])

    chosen = p90()
    with monkeypatch.context() as m:
        m.setattr(LineSource, "laid_pitch_matters", lambda self, spacing: False)
        laid = p90()
    ridge_fit = SurfaceGeometry.ridge_fit
    with monkeypatch.context() as m:
        m.setattr(SurfaceGeometry, "ridge_fit",
                  lambda self, spacing, laid=True: ridge_fit(self, spacing, False))
        blended = p90()
    assert blended < laid  # the fixture reproduces the case
    assert chosen <= blended + 1e-9


CORNER_HOLES = ((-13.5, -8.0), (-13.5, 8.0), (13.5, -8.0), (13.5, 8.0))


def test_a_ray_beside_a_neck_stops_at_the_ridge_it_crosses() -> None:
    """On that plate a ray from the rim beside a corner hole crosses the ridge of the
    strip between the rim and the hole (about 3 mm), then runs past the hole into the
    body, whose boundary distance is deeper: the strip is read at the first peak of the
    distance along the ray (5 mm and less at the median), not at the deepest one (the body
    behind: 7-12 mm, two lines too many in the strip)."""
    v, f = plate_with_holes(38.0, 25.0, 1.5, h=0.5, centres=CORNER_HOLES)
    b = band_across(v, f, boundary_distance(v, f, backend="eikonal"))
    dx = np.min([np.abs(v[:, 0] - cx) for cx, _ in CORNER_HOLES], axis=0)
    beside = (np.abs(v[:, 1]) >= 11.9) & (dx > 1.0) & (dx < 2.1)
    assert beside.sum() > 20
    assert np.median(b[beside]) <= 5.0
    assert np.percentile(b[beside], 75) <= 5.5


def test_a_body_beside_a_neck_keeps_its_width() -> None:
    """A plate 38 x 25 mm with a small hole near each corner (a machined plate): the necks
    between the holes and the rim are about 3 mm wide. The body beside them reads its own
    width (the ray from the left rim crosses the ridge at half the plate's height), not
    the neck's width plus the way from it, which left it too few lines."""
    v, f = plate_with_holes(38.0, 25.0, 1.5, h=0.5, centres=CORNER_HOLES)
    b = band_across(v, f, boundary_distance(v, f, backend="eikonal"))
    body = (np.abs(v[:, 0] + 16.0) < 1.0) & (np.abs(v[:, 1]) < 2.0)
    assert body.sum() > 5
    assert np.all(b[body] > 20.0)


def test_a_plate_with_holes_near_its_rim_is_covered() -> None:
    """That plate printed as one contour layer: with the body's width read at the neck's
    the rings from the rim and the holes stopped short of its middle, 21 % of the layer
    bare and 15 % covered twice; now the rings fill it."""
    v, f = plate_with_holes(38.0, 25.0, 1.5, h=0.5, centres=CORNER_HOLES)
    layers = Layers(v, f, np.zeros(len(f), np.int32), np.full(len(v), 0.6),
                    np.tile([0.0, 0.0, 1.0], (len(v), 1)))
    res = compute_toolpath(layers, JobConfig(), PROFILE, measure_baselines=False, workers=1)
    cov = layer_coverage(layers, res.toolpath, max_samples=20_000)
    assert cov.gap[0] < 0.11 and cov.overlap[0] < 0.09
    assert abs(res.report["layer_volume_error"]) < 0.01


def lobed_disc(radius: float, half: float, length: float, h: float = 0.5
               ) -> tuple[np.ndarray, np.ndarray]:
    """Flat disc of ``radius`` with a lobe ``2 half`` wide reaching ``length`` beyond it
    and ending in a half circle (an ear on a head), edge about h (mm)."""
    from scipy.spatial import Delaunay

    from tests.slicer.toolpath.pattern_meshes import flat_mesh

    def inside(p: np.ndarray, pad: float = 0.0) -> np.ndarray:
        x = np.clip(p[:, 0], 0.0, radius + length)
        return ((np.hypot(p[:, 0], p[:, 1]) < radius - pad)
                | (np.hypot(p[:, 0] - x, p[:, 1]) < half - pad))

    xs = np.arange(-radius, radius + length + half + h, h)
    ys = np.arange(-radius, radius + h, h * np.sqrt(3) / 2)
    p = np.concatenate([np.column_stack([xs + (0.5 * h if i % 2 else 0.0), np.full(len(xs), y)])
                        for i, y in enumerate(ys)])
    p = p[inside(p, 0.5 * h)]
    a = np.linspace(0, 2 * np.pi, int(2 * np.pi * radius / h), endpoint=False)
    circle = radius * np.column_stack([np.cos(a), np.sin(a)])
    circle = circle[~((circle[:, 0] > 0) & (np.abs(circle[:, 1]) < half))]
    end = radius + length
    t = np.arange(np.sqrt(radius**2 - half**2), end, h)
    sides = np.concatenate([np.column_stack([t, np.full(len(t), s * half)]) for s in (1, -1)])
    b = np.linspace(-np.pi / 2, np.pi / 2, int(np.pi * half / h), endpoint=False)
    cap = np.column_stack([end + half * np.cos(b), half * np.sin(b)])
    p = np.concatenate([p, circle, sides, cap])
    tri = Delaunay(p).simplices
    return flat_mesh(p, tri[inside(p[tri].mean(axis=1))])


def _lobe_layer(v: np.ndarray, f: np.ndarray) -> tuple[float, float, float]:
    """Contour width error p50, p90 and volume error of one flat layer (H 0.6 mm)."""
    layers = Layers(v, f, np.zeros(len(f), np.int32), np.full(len(v), 0.6),
                    np.tile([0.0, 0.0, 1.0], (len(v), 1)))
    res = compute_toolpath(layers, JobConfig(), PROFILE, measure_baselines=False, workers=1)
    err = res.report["width_error"]["contour"]
    return float(err["p50"]), float(err["p90"]), float(res.report["layer_volume_error"])


@pytest.mark.parametrize("capped", [True, False])
def test_a_lobe_shorter_than_the_blend_gets_the_lines_it_holds(
        capped: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """A disc 18 mm across (7-8 lines) with a lobe 7 mm wide (3 lines) reaching 5 mm
    beyond it: the count blended over two spacings carries the disc's into the lobe, 4
    lines (two rings, no middle line), the outer ring's sides two spacings apart (p90
    41 %, suzanne's ears on her top layers). Capped by the lobe's own width, a ring and
    the middle line (p90 9 %). Not capped (the check that the fixture reproduces the
    failure), the p90 stays far off."""
    if not capped:
        monkeypatch.setattr(ridge_fit, "SLACK", 1e6)
    _, p90, volume = _lobe_layer(*lobed_disc(9.0, 3.5, 5.0))
    if capped:
        assert p90 <= 0.12 and abs(volume) <= 0.01
    else:
        assert p90 >= 0.3
