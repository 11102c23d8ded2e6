"""Contour rings printed as one spiral: coverage, surface and volume on analytic layers."""

from __future__ import annotations

import numpy as np
import pytest

from core.stages import Layers, Pattern
from slicer.config import JobConfig
from slicer.toolpath.build import compute_toolpath
from slicer.toolpath.coverage import layer_coverage
from slicer.toolpath.ridge import inside_polygon

from .test_build import PROFILE, cap_stack, disc_mesh


def _flat(v: np.ndarray, f: np.ndarray) -> Layers:
    return Layers(v, f.astype(np.int64), np.zeros(len(f), np.int64), np.full(len(v), 0.6),
                  np.tile([0.0, 0.0, 1.0], (len(v), 1)))


@pytest.mark.parametrize("radius", [20.0, 16.0])
def test_spiral_covers_a_disc_once(radius: float) -> None:
    # discs of 8 and 6 rings at W = 2.33 mm: joined by connectors each ring's seam is
    # covered twice (about W x W) and the volume match spreads the rings to pay for it; as
    # one spiral neither happens
    layers = _flat(*disc_mesh(radius, 0.8))
    out = {}
    for spiral in (False, True):
        job = JobConfig().with_overrides(toolpath={"spiral_rings": spiral})
        res = compute_toolpath(layers, job, PROFILE, measure_baselines=False, workers=1)
        cov = layer_coverage(layers, res.toolpath)
        assert abs(res.report["layer_volume_error"]) < 0.01
        assert res.report["extrusion_starts"]["total"] == 1
        out[spiral] = (cov.gap[0], cov.overlap[0], res.report["width_error"]["contour"]["p90"])
    gap, overlap, p90 = out[True]
    assert gap <= 0.03 and overlap <= 0.03
    assert gap + overlap < 0.6 * (out[False][0] + out[False][1])
    assert p90 <= out[False][2]


def test_an_elongated_layer_gets_its_ridge_covered() -> None:
    # a 32 x 20 mm ellipse: the innermost ring is a long loop around the ridge, whose
    # inside the rings leave bare; the spiral ends with a line along the ridge
    v, f = disc_mesh(10.0, 0.5)
    layers = _flat(v * np.array([1.6, 1.0, 1.0]), f)
    out = {}
    for spiral in (False, True):
        job = JobConfig().with_overrides(toolpath={"spiral_rings": spiral})
        res = compute_toolpath(layers, job, PROFILE, measure_baselines=False, workers=1)
        assert abs(res.report["layer_volume_error"]) < 0.01
        cov = layer_coverage(layers, res.toolpath)
        out[spiral] = (cov.gap[0], cov.overlap[0])
    assert max(out[True]) <= 0.03
    assert sum(out[True]) < sum(out[False])


def test_a_band_between_two_boundaries_keeps_its_connectors() -> None:
    layers = _flat(*disc_mesh(16.0, 0.8, inner=6.0))
    tps = [compute_toolpath(layers, JobConfig().with_overrides(toolpath={"spiral_rings": s}),
                            PROFILE, measure_baselines=False, workers=1).toolpath
           for s in (False, True)]
    assert np.array_equal(tps[0].position, tps[1].position)


def test_blends_stay_on_a_curved_layer() -> None:
    # spherical caps of radius 30 mm: every extruding waypoint (rings, blends, the centre
    # line) lies on its sphere, and the layer is still covered
    layers = cap_stack(1, r0=30.0, cone_deg=35.0)
    res = compute_toolpath(layers, JobConfig(), PROFILE, measure_baselines=False, workers=1)
    tp = res.toolpath
    ext = tp.extrude & (tp.pattern == Pattern.CONTOUR)
    assert np.all(np.abs(np.linalg.norm(tp.position[ext], axis=1) - 30.0) < 0.02)
    cov = layer_coverage(layers, tp)
    assert cov.gap[0] <= 0.03 and cov.overlap[0] <= 0.03
    assert res.report["extrusion_starts"]["total"] == 1


def test_inside_a_polygon_with_a_notch() -> None:
    # a 4 x 4 square with a 2 x 2 notch cut from the top right corner
    poly = np.array([[0, 0], [4, 0], [4, 2], [2, 2], [2, 4], [0, 4]], dtype=np.float64)
    pts = np.array([[1, 1], [3, 1], [1, 3], [3, 3], [5, 1], [-1, 2]], dtype=np.float64)
    assert inside_polygon(pts, poly).tolist() == [True, True, True, False, False, False]
