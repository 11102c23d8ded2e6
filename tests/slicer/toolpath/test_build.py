"""Whole-model toolpath on hand-made layer stacks (no tetrahedralisation)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.spatial import Delaunay, cKDTree

from core.stages import Layers, Pattern
from slicer.config import JobConfig
from slicer.extrusion import load_profile
from slicer.toolpath.build import compute_toolpath
from slicer.toolpath.layer_build import layer_pattern
from slicer.toolpath.results import ToolpathResult
from slicer.toolpath.stripe_joins import RIM_INSET
from tests.slicer.toolpath.pattern_meshes import (
    eccentric_annulus,
    flat_mesh,
    plate_with_holes,
    sliver_disc,
)

PROFILE = load_profile("ecoflex-0030")


def disc_mesh(radius: float, h: float, inner: float = 0.0) -> tuple[
    NDArray[np.float64], NDArray[np.int32]
]:
    """Flat disc (or annulus) in z = 0, rings of points about h apart, faces normal +z."""
    pts = [np.zeros((1, 2))] if inner == 0.0 else []
    r0 = inner if inner > 0 else h
    for r in np.arange(r0, radius + 0.5 * h, h):
        r = min(r, radius)
        n = max(int(np.ceil(2 * np.pi * r / h)), 6)
        a = np.linspace(0, 2 * np.pi, n, endpoint=False) + 0.37 * r
        pts.append(r * np.column_stack([np.cos(a), np.sin(a)]))
    p = np.concatenate(pts)
    tri = Delaunay(p).simplices
    if inner > 0:
        tri = tri[np.linalg.norm(p[tri].mean(axis=1), axis=1) > inner]
    return flat_mesh(p, tri)


def flat_layer(v: NDArray[np.float64], f: NDArray[np.int32], height: float) -> Layers:
    """One flat layer (layer 0) of constant height H (mm), normals +z."""
    return Layers(v, f, np.zeros(len(f), np.int32), np.full(len(v), height),
                  np.tile([0.0, 0.0, 1.0], (len(v), 1)))


def stripe_layer_toolpath(v: NDArray[np.float64], f: NDArray[np.int32], height: float
                          ) -> ToolpathResult:
    """The toolpath of one flat layer printed as a stripe layer (no baselines)."""
    cfg = JobConfig().with_overrides(toolpath={"first_pattern": "stripe"})
    return compute_toolpath(flat_layer(v, f, height), cfg, PROFILE, measure_baselines=False,
                            workers=1)


def disc_stack(n_layers: int, radius: float = 12.0, h: float = 1.0, base_h: float = 0.6,
               slope: float = 0.15) -> Layers:
    """Flat discs at z = k * base_h, layer height H = base_h + slope * x / radius."""
    v, f = disc_mesh(radius, h)
    vs, fs, fl, hs = [], [], [], []
    for k in range(n_layers):
        vv = v.copy()
        vv[:, 2] = k * base_h
        vs.append(vv)
        fs.append(f + k * len(v))
        fl.append(np.full(len(f), k))
        hs.append(base_h + slope * v[:, 0] / radius)
    verts = np.concatenate(vs)
    return Layers(verts, np.concatenate(fs), np.concatenate(fl), np.concatenate(hs),
                  np.tile([0.0, 0.0, 1.0], (len(verts), 1)))


def cap_stack(n_layers: int, r0: float = 30.0, height: float = 0.6, cone_deg: float = 25.0,
              h: float = 1.0) -> Layers:
    """Concentric spherical caps |p| = r0 + k * height (polar angle < cone), growth radial."""
    v, f = disc_mesh(1.0, h / (r0 * np.radians(cone_deg)))
    theta = np.linalg.norm(v[:, :2], axis=1) * np.radians(cone_deg)
    phi = np.arctan2(v[:, 1], v[:, 0])
    unit = np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi),
                            np.cos(theta)])
    vs, fs, fl = [], [], []
    for k in range(n_layers):
        vs.append(unit * (r0 + k * height))
        fs.append(f + k * len(v))
        fl.append(np.full(len(f), k))
    verts = np.concatenate(vs)
    return Layers(verts, np.concatenate(fs), np.concatenate(fl),
                  np.full(len(verts), height), np.tile(unit, (n_layers, 1)))


@pytest.fixture(scope="module")
def discs() -> tuple[Layers, ToolpathResult]:
    layers = disc_stack(4)
    return layers, compute_toolpath(layers, JobConfig(), PROFILE, workers=1)


@pytest.fixture(scope="module")
def discs_perimeter() -> ToolpathResult:
    config = JobConfig().with_overrides(toolpath={"stripe_perimeter": True})
    return compute_toolpath(disc_stack(4), config, PROFILE, workers=1)


@pytest.fixture(scope="module")
def caps() -> tuple[Layers, ToolpathResult]:
    layers = cap_stack(2)
    return layers, compute_toolpath(layers, JobConfig(), PROFILE, measure_baselines=False,
                                    workers=1)


def test_patterns_alternate() -> None:
    assert [layer_pattern(i, "contour") for i in range(4)] == [0, 1, 0, 1]
    assert [layer_pattern(i, "stripe") for i in range(3)] == [1, 0, 1]


def test_waypoints_on_flat_layers_with_unit_normals(discs: tuple[Layers, ToolpathResult]) -> None:
    _, res = discs
    tp = res.toolpath
    ext = tp.extrude
    assert np.all(np.abs(tp.position[ext, 2] - 0.6 * tp.layer[ext]) < 0.01)
    assert np.allclose(np.linalg.norm(tp.normal, axis=1), 1.0, atol=1e-9)
    assert np.allclose(tp.normal[ext], [0.0, 0.0, 1.0], atol=1e-9)
    assert np.all(np.linalg.norm(tp.position[ext, :2], axis=1) <= 12.0 + 1e-6)
    assert set(np.unique(tp.layer)) == {0, 1, 2, 3}
    assert np.all(np.diff(tp.layer) >= 0)
    assert np.all(np.diff(tp.path) >= 0)
    assert np.all(tp.pattern[tp.layer % 2 == 0] == Pattern.CONTOUR)
    assert np.all(tp.pattern[tp.layer % 2 == 1] == Pattern.STRIPE)


def test_width_follows_eq4(discs: tuple[Layers, ToolpathResult]) -> None:
    tp = discs[1].toolpath
    assert np.allclose(tp.width, PROFILE.rate_mm3_s / (tp.height * tp.speed), rtol=1e-9)
    ext = tp.extrude
    # H on the flat layer is the linear field base_h + slope * x / radius
    assert np.allclose(tp.height[ext], 0.6 + 0.15 * tp.position[ext, 0] / 12.0, atol=1e-9)
    contour = tp.pattern == Pattern.CONTOUR
    assert np.allclose(tp.speed[contour], PROFILE.speed_at(tp.height[contour]))
    # stripes are printed as wide as their spacing (pitch_width): the speed scales W
    scale = PROFILE.speed_at(tp.height) / tp.speed
    assert np.all((scale >= 0.5 - 1e-9) & (scale <= 1.5 + 1e-9))


def test_volume_matches_required(discs: tuple[Layers, ToolpathResult]) -> None:
    _, res = discs
    rep = res.report
    assert abs(rep["deposited_volume_mm3"] / rep["required_volume_mm3"] - 1.0) < 0.02
    area = np.pi * 12.0**2
    # required = integral of H over the layers (H linear in x averages to base_h)
    assert rep["required_volume_mm3"] == pytest.approx(4 * 0.6 * area, rel=0.02)
    for stat in res.layer_stats:
        assert abs(stat["deposited_mm3"] / stat["required_mm3"] - 1.0) < 0.02
    assert rep["component_volume_error"]["max_abs"] < 0.02


def _tangents(pos: NDArray[np.float64], keep: NDArray[np.bool_], path: NDArray[np.int32]
              ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    d = np.diff(pos, axis=0)
    ok = keep[1:] & keep[:-1] & (path[1:] == path[:-1])
    mid = 0.5 * (pos[1:] + pos[:-1])
    t = d[ok] / np.maximum(np.linalg.norm(d[ok], axis=1, keepdims=True), 1e-12)
    return mid[ok], t


def test_consecutive_layers_cross(discs: tuple[Layers, ToolpathResult]) -> None:
    tp = discs[1].toolpath
    for k in range(3):
        ma, ta = _tangents(tp.position, tp.extrude & (tp.layer == k), tp.path)
        mb, tb = _tangents(tp.position, tp.extrude & (tp.layer == k + 1), tp.path)
        _, j = cKDTree(ma[:, :2]).query(mb[:, :2])
        ang = np.degrees(np.arccos(np.clip(np.abs(np.einsum("ij,ij->i", ta[j], tb)), 0, 1)))
        assert np.median(ang) >= 60.0, (k, np.median(ang))


def test_travel_is_lifted_and_not_extruding(discs: tuple[Layers, ToolpathResult]) -> None:
    tp = discs[1].toolpath
    trav = ~tp.extrude
    assert np.any(trav)  # at least between layers
    # every travel waypoint is at least one layer height above the layer just printed
    # (a travel move belongs to the layer it leaves)
    assert np.all(tp.position[trav, 2] >= 0.6 * tp.layer[trav] + tp.height[trav] - 1e-9)
    # travel waypoints have their own path ids
    assert not set(np.unique(tp.path[trav])) & set(np.unique(tp.path[~trav]))


def test_one_extrusion_start_per_contour_disc(discs: tuple[Layers, ToolpathResult]) -> None:
    for stat in discs[1].layer_stats:
        if stat["pattern"] == "contour":
            assert stat["extrusion_starts"] == [1]
    rep = discs[1].report
    assert rep["paths"] == rep["extrusion_starts"]["total"]


def test_report_keys_and_measured_width_error(discs: tuple[Layers, ToolpathResult]) -> None:
    rep = discs[1].report
    for key in ("waypoints", "paths", "length_mm", "deposited_volume_mm3", "volume_error",
                "width_error", "width_error_undeformed", "width_error_poisson_stripe"):
        assert key in rep
    for pat in ("contour", "stripe"):
        we = rep["width_error"][pat]
        assert we["n"] > 0 and 0 <= we["p50"] <= we["p90"] <= we["p95"]
    # deformation makes contour spacing follow the variable W much better than direct lines
    assert rep["width_error"]["contour"]["p90"] < rep["width_error_undeformed"]["contour"]["p90"]
    assert rep["width_error"]["contour"]["p90"] < 0.2
    assert rep["width_error_poisson_stripe"]["n"] > 0
    assert 0.5 <= rep["tau"]["min"] <= rep["tau"]["max"] <= 2.0
    assert len(rep["per_layer"]) == 4
    json.dumps(rep)  # the report section is plain JSON


def test_baselines_are_reported_as_skipped(discs: tuple[Layers, ToolpathResult]) -> None:
    layers, full = discs
    skipped = compute_toolpath(layers, JobConfig(), PROFILE, measure_baselines=False, workers=1)
    rep = skipped.report
    assert full.report["baselines_measured"] and not rep["baselines_measured"]
    assert rep["width_error_undeformed"]["contour"]["n"] == 0
    assert rep["width_error_poisson_stripe"]["n"] == 0
    # nothing printed depends on them
    assert np.array_equal(skipped.toolpath.position, full.toolpath.position)
    assert rep["width_error"] == full.report["width_error"]


def test_curved_caps_on_layer_with_radial_normals(caps: tuple[Layers, ToolpathResult]) -> None:
    _, res = caps
    tp = res.toolpath
    ext = tp.extrude
    radius = np.linalg.norm(tp.position, axis=1)
    target = 30.0 + 0.6 * tp.layer
    # faces are chords of the sphere: distance to the *mesh* is what counts; the sagitta
    # of a 1 mm edge on r = 30 mm is 0.004 mm, so the sphere is within 0.01 mm too
    assert np.all(np.abs(radius[ext] - target[ext]) < 0.01)
    radial = tp.position / radius[:, None]
    assert np.all(np.einsum("ij,ij->i", tp.normal[ext], radial[ext]) > 0.99)
    trav = ~ext
    assert np.all(radius[trav] >= 30.0 + 0.6 * tp.layer[trav] + 0.6 - 1e-6)
    assert abs(res.report["layer_volume_error"]) < 0.02


def test_parallel_equals_serial() -> None:
    layers = disc_stack(4, radius=8.0)
    cfg = JobConfig()
    serial = compute_toolpath(layers, cfg, PROFILE, measure_baselines=False, workers=1)
    parallel = compute_toolpath(layers, cfg, PROFILE, measure_baselines=False, workers=2)
    for name, arr in serial.toolpath.arrays().items():
        assert np.array_equal(arr, parallel.toolpath.arrays()[name]), name


def test_closed_component_is_skipped_with_reason() -> None:
    """A layer component without boundary (a closed tetrahedron surface) cannot carry
    boundary-conformal lines: it is reported, the rest of the layer is still printed."""
    disc = disc_stack(1, radius=6.0)
    tet_v = np.array([[20.0, 0, 0], [22, 0, 0], [20, 2, 0], [20, 0, 2]])
    tet_f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]) + len(disc.vertices)
    layers = Layers(
        np.concatenate([disc.vertices, tet_v]),
        np.concatenate([disc.faces, tet_f]),
        np.zeros(len(disc.faces) + 4, np.int32),
        np.concatenate([disc.vertex_height, np.full(4, 0.6)]),
        np.concatenate([disc.vertex_direction, np.tile([0, 0, 1.0], (4, 1))]),
    )
    res = compute_toolpath(layers, JobConfig(), PROFILE, measure_baselines=False, workers=1)
    assert res.status == "failed-components"
    assert res.report["failed_components"]["count"] == 1
    assert "boundary" in res.report["failed_components"]["reasons"][0]
    tp = res.toolpath
    assert np.all(np.linalg.norm(tp.position[tp.extrude, :2], axis=1) <= 6.0 + 1e-6)
    assert res.report["extrusion_starts"]["total"] >= 1


def test_heights_below_profile_are_raised() -> None:
    layers = disc_stack(1, radius=6.0, base_h=0.6, slope=0.55)  # H from 0.05 to 1.15 mm
    res = compute_toolpath(layers, JobConfig(), PROFILE, measure_baselines=False, workers=1)
    tp = res.toolpath
    lo, _ = PROFILE.layer_height_range
    assert np.all(tp.height >= lo - 1e-12)
    assert np.all(np.isfinite(tp.width)) and tp.width.max() < 10.0
    assert np.allclose(tp.width, PROFILE.rate_mm3_s / (tp.height * tp.speed))
    assert res.report["height_out_of_profile_fraction"] > 0


def test_heights_above_profile_keep_their_slab_spacing() -> None:
    """A slab thicker than the profile covers: the speed saturates at the slowest, H stays
    as sliced and W = C / (H v) is the spacing at which that filament fills the slab, so
    the contours lie about W apart (clamping H to the table made W twice too wide and the
    volume match packed the lines at half of it)."""
    h = 3.0  # profile: H up to 1.65 mm
    layers = disc_stack(1, radius=12.0, base_h=h, slope=0.0)
    res = compute_toolpath(layers, JobConfig(), PROFILE, measure_baselines=False, workers=1)
    tp = res.toolpath
    sel = tp.extrude
    v_min = float(PROFILE.speed[0])
    assert np.allclose(tp.height[sel], h, rtol=1e-3)
    assert np.allclose(tp.speed[sel], v_min, rtol=1e-3)
    assert np.allclose(tp.width, PROFILE.rate_mm3_s / (tp.height * tp.speed))
    w = PROFILE.rate_mm3_s / (h * v_min)
    assert np.median(tp.width[sel]) == pytest.approx(w, rel=0.05)
    assert res.report["width_error"]["contour"]["p50"] < 0.05
    assert abs(res.report["layer_volume_error"]) < 0.02
    assert res.report["height_out_of_profile_fraction"] == pytest.approx(1.0)


@pytest.mark.parametrize("narrow", [False, True])
def test_stripes_stop_inside_the_boundary(narrow: bool) -> None:
    config = JobConfig().with_overrides(toolpath={"stripe_perimeter": False,
                                                  "narrow_joins": narrow})
    tp = compute_toolpath(disc_stack(2), config, PROFILE, measure_baselines=False,
                          workers=1).toolpath
    sel = tp.extrude & (tp.pattern == Pattern.STRIPE)
    gap = 12.0 - np.linalg.norm(tp.position[sel, :2], axis=1)
    # the U-turn's band (W / 2 each side of its line; with narrow joins W / 4) ends at the
    # boundary; a short stripe is cut back by at most a quarter of its length per end
    inset = RIM_INSET if narrow else 0.5
    ratio = gap / tp.width[sel]
    assert np.percentile(ratio, 2) >= 0.7 * inset
    assert ratio.min() > 0.05
    assert ratio.min() < inset + 0.1


def test_stripe_layer_has_a_perimeter_loop(discs_perimeter: ToolpathResult) -> None:
    """stripe_perimeter: a stripe layer of a flat disc gets one loop half a spacing inside
    the boundary, all the way round, and no stripe comes closer to the boundary than about a
    spacing (the loop's band lies between)."""
    res = discs_perimeter
    tp = res.toolpath
    for stat in res.layer_stats:
        if stat["pattern"] != "stripe":
            continue
        sel = tp.extrude & (tp.layer == stat["layer"])
        assert np.all(tp.pattern[sel] == Pattern.STRIPE)
        pos, w = tp.position[sel], tp.width[sel]
        half = 0.5 * stat["tau"][0] * w  # spacing / 2
        gap = 12.0 - np.linalg.norm(pos[:, :2], axis=1)
        assert gap.min() > 0.4 * w.min()
        ring = np.abs(gap - half) < 0.15 * w
        # the loop: all the way round, and nothing else between it and the stripes
        angle = np.arctan2(pos[ring, 1], pos[ring, 0])
        assert np.all(np.histogram(angle, bins=36, range=(-np.pi, np.pi))[0] > 0)
        assert np.all(gap[~ring] > 0.9 * w[~ring])
        # the loop runs along one iso-distance: its points are not scattered radially
        assert np.ptp(gap[ring] / w[ring]) < 0.25
        # one extrusion start per component: the loop is joined to the stripes
        assert stat["extrusion_starts"] == [1]
        # the volume match covers loop and stripes
        assert abs(stat["deposited_mm3"] / stat["required_mm3"] - 1) < 0.02


def test_narrow_band_stripes_get_no_perimeter_loop() -> None:
    """stripe_perimeter only where the layer is wide: on an annulus 4.3 W across (W = 2.33
    mm at H = 0.6 mm), two loops and clipped stubs would be mostly connectors, so the stripe
    layer is the same with and without the option."""
    v, f = disc_mesh(20.0, 0.6, inner=10.0)
    layers = flat_layer(v, f, 0.6)
    runs = [compute_toolpath(layers, JobConfig().with_overrides(
        toolpath={"first_pattern": "stripe", "stripe_perimeter": on}), PROFILE,
        measure_baselines=False, workers=1).toolpath for on in (False, True)]
    assert np.all(runs[0].pattern == Pattern.STRIPE)
    assert np.array_equal(runs[0].position, runs[1].position)


def test_thin_band_gets_a_centre_line() -> None:
    """An annulus about one width wide (W = 4.5 mm at H = 1 mm) cannot take stripes (they
    vanish when cut back by W / 2) nor spaced contours: one loop along its middle."""
    res = stripe_layer_toolpath(*disc_mesh(14.0, 0.5, inner=10.0), 1.0)
    assert res.report["thin_fallback"]["centre-line"] == 1
    tp = res.toolpath
    r = np.linalg.norm(tp.position[tp.extrude, :2], axis=1)
    assert np.allclose(r, 12.0, atol=0.05)  # the middle (harmonic 1/2: 11.83, geometric mean)
    assert np.all(tp.pattern == Pattern.CONTOUR)
    assert res.report["extrusion_starts"]["total"] == 1
    # volume: the 4.5 mm line is narrowed to the 4 mm band by a faster nozzle (W = C / (H v)
    # still holds), so the band gets its volume, not 12 % more
    assert abs(res.report["layer_volume_error"]) < 0.01
    ext = tp.extrude
    assert np.allclose(tp.width[ext], 4.0, rtol=0.03)
    assert np.allclose(tp.width * tp.height * tp.speed, PROFILE.rate_mm3_s)
    assert np.all(tp.speed[ext] > PROFILE.speed_at(tp.height[ext]))
    # width error of a lone line: its band (4 mm), not the distance across the hole to the
    # far side of its own loop, against the 4 mm it prints; against the profile's W(H) =
    # 4.5 mm in the nominal measure
    err = res.report["width_error"]["contour"]
    assert err["p50"] < 0.02 and err["p95"] < 0.04
    w = float(PROFILE.rate_mm3_s / PROFILE.speed_at(np.array([1.0]))[0])
    nominal = res.report["width_error_nominal"]["contour"]
    assert nominal["p50"] == pytest.approx(abs(4.0 - w) / w, abs=0.02)
    assert nominal["p95"] < abs(4.0 - w) / w + 0.04
    assert res.report["width_error_no_neighbour_fraction"]["contour"] == 1.0


def test_centre_line_prints_as_wide_as_its_band() -> None:
    """A band widening from 3 to 4.4 mm around a hole (W = 4.55 mm at H = 1 mm) holds one
    line; with pitch_width it prints as wide as the band where it runs, without it one
    width fits the whole band's volume."""
    v, f = eccentric_annulus(radius=14.0, hole=10.3, offset=0.7, h=0.5)
    widths, p90 = {}, {}
    for on in (True, False):
        job = JobConfig().with_overrides(toolpath={"first_pattern": "stripe",
                                                   "pitch_width": on})
        res = compute_toolpath(flat_layer(v, f, 1.0), job, PROFILE, measure_baselines=False,
                               workers=1)
        assert res.report["thin_fallback"]["centre-line"] == 1
        assert abs(res.report["layer_volume_error"]) < 0.01
        tp = res.toolpath
        ext = tp.extrude
        x = tp.position[ext, 0]
        widths[on] = (np.median(tp.width[ext][x > 10.0]), np.median(tp.width[ext][x < -10.0]))
        assert np.allclose(tp.width * tp.height * tp.speed, PROFILE.rate_mm3_s)
        p90[on] = res.report["width_error"]["contour"]["p90"]
    assert p90[True] < 0.06
    assert p90[True] < 0.5 * p90[False]
    assert widths[True][0] == pytest.approx(3.0, rel=0.05)
    assert widths[True][1] == pytest.approx(4.4, rel=0.05)
    assert widths[False][0] == pytest.approx(widths[False][1], rel=0.01)


def test_width_scalings_compound_within_the_limit() -> None:
    # a centre line 1.5 W wide (its band) whose flow fit asks 1.5x more still prints at most
    # 1.5 W(H): W = C / (H v) with v never below the profile's speed / 1.5
    from slicer.config import ToolpathConfig
    from slicer.toolpath.component import Component
    from slicer.toolpath.layer_build import split_layers
    from slicer.toolpath.surface_geometry import CENTRE_WIDTH_SCALE

    v, f = disc_mesh(8.0, 1.0)
    layer = split_layers(flat_layer(v, f, 1.0))[0]
    comp = Component(layer, np.arange(len(f)), Pattern.CONTOUR, ToolpathConfig(), PROFILE)
    nominal = PROFILE.speed_at(np.array([1.0, 1.0]))
    lo, hi = CENTRE_WIDTH_SCALE
    wide = comp.flowed_speed(nominal, hi)  # the band's width: 1.5 W
    assert wide == pytest.approx(nominal / hi)
    assert comp.flowed_speed(wide, hi) == pytest.approx(nominal / hi**2)  # unbounded
    assert comp.flowed_speed(wide, hi, nominal) == pytest.approx(nominal / hi)
    assert comp.flowed_speed(nominal, 0.3, nominal) == pytest.approx(nominal / lo)


def test_narrow_band_on_a_stripe_layer_gets_contours() -> None:
    """An annulus 1.7 W wide (W = 4.55 mm at H = 1 mm): stripes across it would be stubs
    shorter than W, so the stripe layer prints it like a contour layer: two fitted loops
    with the band's volume; a disc as wide keeps its stripes."""
    res = stripe_layer_toolpath(*disc_mesh(17.7, 0.5, inner=10.0), 1.0)
    assert res.report["thin_fallback"]["contour"] == 1
    tp = res.toolpath
    assert np.all(tp.pattern == Pattern.CONTOUR)
    r = np.linalg.norm(tp.position[tp.extrude, :2], axis=1)
    assert np.all((r > 10.5) & (r < 17.2))
    assert np.ptp(r) > 0.6 * 4.55  # two loops across the band
    # two lines hold 0.85 W each (15-20 % off the profile's W by construction); they print
    # as wide as the band's pitch (pitch_width), which makes up the volume without a flow fit
    # of the whole component, and about as wide as they lie apart
    assert abs(res.report["layer_volume_error"]) < 0.01
    assert res.report["per_layer"][0]["volume_status"][0] == "converged"
    assert 0.75 * 4.55 < np.median(tp.width[tp.extrude]) < 0.9 * 4.55
    printed, nominal = (res.report[k]["contour"]["p50"]
                        for k in ("width_error", "width_error_nominal"))
    assert 0.1 < nominal < 0.25
    assert printed < 0.5 * nominal
    res = stripe_layer_toolpath(*disc_mesh(7.7, 0.5), 1.0)
    assert np.all(res.toolpath.pattern == Pattern.STRIPE)


def test_band_fitting_holes_are_filled_where_the_layer_is_no_band() -> None:
    """A plate with two holes: thin bands around the holes and a solid junction between
    them. Contours fitted to the band (outer loop against the holes) miss part of the
    junction; the holes get eq. 9's iso-lines, so no area is left farther than 0.8
    spacings from a line, and the component still gets its volume."""
    from dataclasses import replace

    from slicer.toolpath.line_source import UNCOVERED, LineSource

    v, f = plate_with_holes()
    surf = LineSource.of(v, f)
    w = 2.33
    assert not surf.band_fit_covers(w)
    surf = replace(surf, fill_holes=True)
    gap = surf.geometry.line_gap(surf.lines(Pattern.CONTOUR, w))
    assert surf.face_area[gap > UNCOVERED * w].sum() < 0.02 * surf.face_area.sum()
    annulus = LineSource.of(*disc_mesh(20.0, 0.6, inner=10.0))
    assert annulus.band_fit_covers(w)  # a band: nothing to fill
    layers = flat_layer(v, f, 0.6)
    res = compute_toolpath(layers, JobConfig(), PROFILE, measure_baselines=False, workers=1)
    # printed with the holes filled or with eq. 9's contours alone, whichever keeps the
    # spacing better (here the plain contours)
    assert res.report["band_fit_holes_filled"] + res.report["band_fit_dropped"] == 1
    assert abs(res.report["layer_volume_error"]) < 0.01


def test_a_disc_with_slits_is_no_band_and_gets_plain_contours() -> None:
    """A disc with three short slits near its rim (the membrane's dome-top layer): the
    band model (outer loop against the slits) does not cover it, and eq. 9's contours
    from the whole boundary keep their spacing far better than the fitted lines with
    eq. 9's in their holes (p90 79 % before), so the component is printed with those."""
    v, f = disc_mesh(20.0, 0.6)
    centre = v[f].mean(axis=1)
    r = np.linalg.norm(centre[:, :2], axis=1)
    angle = np.arctan2(centre[:, 1], centre[:, 0])
    keep = np.ones(len(f), dtype=bool)
    for a0 in (2.6, 3.14, 3.7):
        keep &= ~((r > 16.5) & (r < 17.3) & (np.abs(angle - a0) < 0.25))
    res = compute_toolpath(flat_layer(v, f[keep], 0.6), JobConfig(), PROFILE,
                           measure_baselines=False, workers=1)
    assert [s["fallback"] for s in res.layer_stats] == [["no-band"]]
    assert res.report["band_fit_dropped"] == 1 and res.report["band_fit_holes_filled"] == 0
    assert res.report["width_error"]["contour"]["p90"] < 0.1
    assert abs(res.report["layer_volume_error"]) < 0.01


def test_variable_height_on_a_curved_layer_is_deformed() -> None:
    """A spherical cap whose layer height grows along x: the width-driven deformation runs,
    waypoints stay on the cap, and the contour spacing follows W far better than lines
    computed directly on the cap."""
    base = cap_stack(1, r0=30.0, cone_deg=30.0)
    height = 0.5 + 0.25 * (base.vertices[:, 0] / 15.0 + 1.0)  # 0.5 .. 1.0 mm
    layers = Layers(base.vertices, base.faces, base.face_layer, height, base.vertex_direction)
    res = compute_toolpath(layers, JobConfig(), PROFILE, workers=1)
    tp = res.toolpath
    assert res.report["deformation_status"].get("skipped", 0) == 0
    ext = tp.extrude
    assert np.all(np.abs(np.linalg.norm(tp.position[ext], axis=1) - 30.0) < 0.01)
    we, wu = res.report["width_error"]["contour"], res.report["width_error_undeformed"]["contour"]
    assert we["p90"] < 0.5 * wu["p90"]
    assert abs(res.report["layer_volume_error"]) < 0.02


def test_band_fitting_on_an_annulus_layer() -> None:
    # a 9.6 mm band with W = 2.33 mm: 4 circles at a 2.4 mm pitch (3 % wide), one path;
    # eq. 9 leaves a gap between the two families that tau closes by packing every loop
    # 13 % too tight
    import dataclasses

    v, f = disc_mesh(16.0, 0.8, inner=6.0)
    layers = Layers(v, f, np.zeros(len(f), np.int64), np.full(len(v), 0.6),
                    np.tile([0.0, 0.0, 1.0], (len(v), 1)))
    reports = []
    for fit in (True, False):
        job = JobConfig()
        # (the eq. 9 baseline without the fit to the local width either, ``ridge_fit.py``)
        job = dataclasses.replace(job, toolpath=dataclasses.replace(
            job.toolpath, fit_bands=fit, fit_ridge=fit))
        res = compute_toolpath(layers, job, PROFILE, measure_baselines=False, workers=1)
        reports.append(res.report)
        assert abs(res.report["layer_volume_error"]) < 0.02
    fitted, eq9 = reports
    assert fitted["width_error"]["contour"]["p90"] < 0.05
    assert fitted["width_error"]["contour"]["p90"] < 0.5 * eq9["width_error"]["contour"]["p90"]
    assert fitted["extrusion_starts"]["total"] == 1


def test_contours_on_a_band_print_as_wide_as_its_pitch() -> None:
    # a band 11 to 13 mm wide at W = 2.33 mm: 5 lines 2.2 mm apart at +x, 5 lines 2.4 mm
    # apart across y = 0, 6 lines 2.17 mm apart at -x. Printed at W(H) they overlap or
    # gap by up to 6 %; printed as wide as the pitch (the speed sets the width) they abut,
    # and the ink follows the band's area
    v, f = eccentric_annulus(hole=8.0, offset=1.0)
    layers = Layers(v, f.astype(np.int64), np.zeros(len(f), np.int64), np.full(len(v), 0.6),
                    np.tile([0.0, 0.0, 1.0], (len(v), 1)))
    reports, paths = [], []
    for pitch_width in (True, False):
        job = JobConfig().with_overrides(toolpath={"pitch_width": pitch_width})
        res = compute_toolpath(layers, job, PROFILE, measure_baselines=False, workers=1)
        assert abs(res.report["layer_volume_error"]) < 0.02
        reports.append(res.report)
        paths.append(res.toolpath)
    (fitted, fixed), (tp, tp_fixed) = reports, paths
    assert fitted["width_error"]["contour"]["p90"] < 0.7 * fixed["width_error"]["contour"]["p90"]
    # against W(H) the lines are where they were
    assert fitted["width_error_nominal"]["contour"]["p90"] == pytest.approx(
        fixed["width_error"]["contour"]["p90"], rel=0.2)
    ext = tp.extrude
    w, x = tp.width[ext], tp.position[ext, 0]
    assert np.ptp(tp_fixed.width[tp_fixed.extrude]) < 1e-9
    spread = fitted["width_over_profile"]
    assert spread["min"] < 0.97 < 1.03 < spread["max"] < 1.5
    assert fixed["width_over_profile"]["max"] - fixed["width_over_profile"]["min"] < 1e-9
    assert np.median(w[np.abs(x) < 3.0]) > 1.05 * np.median(w[x > 12.0])
    assert np.median(w[np.abs(x) < 3.0]) > 1.05 * np.median(w[x < -12.0])
    # eq. 4's W = C / (H v) still holds at every waypoint, speeds within the profile's table
    c = tp.height[ext] * w * tp.speed[ext]
    assert c == pytest.approx(PROFILE.rate_mm3_s, rel=1e-9)
    lo, hi = PROFILE.speed_for_height(np.array(PROFILE.height_range[::-1]))
    assert tp.speed[ext].min() >= lo - 1e-9 and tp.speed[ext].max() <= hi + 1e-9


def test_eikonal_distance_keeps_contour_pitch_on_a_coarse_sliver_mesh() -> None:
    # a 20 mm disc cut into ~2 mm triangles with slivers, as marching tets cut a layer: the
    # heat method's distance wanders near the boundary, the eikonal one follows it
    import dataclasses

    v, f = sliver_disc(20.0, 2.0)
    layers = Layers(v, f.astype(np.int64), np.zeros(len(f), np.int64), np.full(len(v), 0.6),
                    np.tile([0.0, 0.0, 1.0], (len(v), 1)))
    p90 = {}
    for backend in ("eikonal", "heat"):
        job = JobConfig()
        job = dataclasses.replace(job, toolpath=dataclasses.replace(
            job.toolpath, boundary_distance=backend))
        res = compute_toolpath(layers, job, PROFILE, measure_baselines=False, workers=1)
        assert abs(res.report["layer_volume_error"]) < 0.02
        p90[backend] = res.report["width_error"]["contour"]["p90"]
    assert p90["eikonal"] < 0.045
    assert p90["eikonal"] < 0.8 * p90["heat"]


def test_join_factor_is_validated() -> None:
    from slicer.config import ToolpathConfig

    with pytest.raises(ValueError):
        ToolpathConfig(join_factor=0.5)
    assert ToolpathConfig().join_factor >= 2.0


def test_first_layer_beta_applies_to_layer_zero_only() -> None:
    """first_layer_beta = pi/4: layer 0's filaments (w_f = 4 beta / pi W in volume mode) touch
    side by side, printed faster with narrower lines; later layers keep the profile's beta."""
    import dataclasses

    beta0 = float(np.pi / 4)
    # (pitch_width and narrow_joins off: layer 1's stripes and joins keep W(H))
    config = JobConfig().with_overrides(toolpath={"first_layer_beta": beta0,
                                                  "pitch_width": False,
                                                  "narrow_joins": False})
    res = compute_toolpath(disc_stack(2), config, PROFILE, measure_baselines=False, workers=1)
    tp = res.toolpath
    first = dataclasses.replace(PROFILE, beta=beta0)
    for layer, profile in ((0, first), (1, PROFILE)):
        sel = tp.extrude & (tp.layer == layer)
        assert np.allclose(tp.speed[sel], profile.speed_at(tp.height[sel]))
        assert np.allclose(tp.width[sel], profile.width(tp.height[sel]))
    w0 = np.median(tp.width[tp.extrude & (tp.layer == 0)])
    assert w0 < 0.5 * np.median(tp.width[tp.extrude & (tp.layer == 1)])
    assert abs(res.report["layer_volume_error"]) < 0.02
    with pytest.raises(Exception, match="first_layer_beta"):
        JobConfig().with_overrides(toolpath={"first_layer_beta": 0.2})


def _one_layer(v: NDArray[np.float64], f: NDArray[np.int32]) -> tuple[ToolpathResult, Layers]:
    layers = flat_layer(v, f, 1.0)
    return compute_toolpath(layers, JobConfig(), PROFILE, measure_baselines=False,
                            workers=1), layers


def test_a_strip_one_and_a_half_widths_wide_prints_one_line_as_wide_as_it() -> None:
    """A strip without holes 1.4 W wide holds one line along its middle, end to end, printed
    as wide as the strip (before: a loop whose two sides lay 0.4 W apart, p90 35 %, 3 %
    of the strip bare)."""
    from slicer.toolpath.coverage import layer_coverage
    from tests.slicer.toolpath.test_medial import strip

    w = float(PROFILE.width(np.array([1.0]))[0])
    res, layers = _one_layer(*strip(60.0, 1.4 * w, 0.6))
    assert res.report["thin_fallback"]["centre-line"] == 1
    assert res.report["extrusion_starts"]["total"] == 1
    assert abs(res.report["layer_volume_error"]) < 0.01
    assert res.report["width_error"]["contour"]["p90"] < 0.02
    ext = res.toolpath.extrude
    assert np.allclose(np.median(res.toolpath.width[ext]), 1.4 * w, rtol=0.02)
    cov = layer_coverage(layers, res.toolpath)
    assert cov.gap[0] < 0.01 and cov.overlap[0] < 0.01


def test_a_sharp_wedge_prints_one_line_following_its_width() -> None:
    """A wedge 1.4 W wide at its base, 7 deg at its tip: one line along the bisector into the
    tip, as wide as the wedge wherever a filament can be (down to half W; before: rings
    pinched at the tip, p90 71 %, 32 % bare and 22 % covered twice), the volume matched."""
    from slicer.toolpath.coverage import layer_coverage
    from slicer.toolpath.surface_geometry import CENTRE_WIDTH_SCALE
    from tests.slicer.toolpath.test_medial import wedge

    w = float(PROFILE.width(np.array([1.0]))[0])
    v, f = wedge(60.0, float(np.degrees(np.arctan(0.7 * w / 60.0))), 0.5)
    res, layers = _one_layer(v, f)
    assert res.report["thin_fallback"]["centre-line"] == 1
    assert abs(res.report["layer_volume_error"]) < 0.01
    tp = res.toolpath
    ext = tp.extrude & (tp.position[:, 0] < 59.0)
    local = 2.0 * tp.position[ext, 0] * 0.7 * w / 60.0  # the wedge's width there
    printable = local >= CENTRE_WIDTH_SCALE[0] * w
    assert np.allclose(tp.width[ext][printable], local[printable], rtol=0.1)
    # narrower than half a filament (the tip's last 21 mm): the narrowest filament
    assert np.allclose(tp.width[ext][~printable], CENTRE_WIDTH_SCALE[0] * w, rtol=0.05)
    assert res.report["width_error"]["contour"]["p50"] < 0.05
    cov = layer_coverage(layers, tp)
    assert cov.overlap[0] < 0.01 and cov.gap[0] < 0.06
