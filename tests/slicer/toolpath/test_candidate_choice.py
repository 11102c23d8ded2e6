"""Alternative lines per component, and the one kept (analytic flat layers)."""

from __future__ import annotations

import numpy as np
import pytest

import slicer.toolpath.candidate_choice as candidate_choice
from core.stages import Pattern
from slicer.config import JobConfig
from slicer.status import ComponentFallback
from slicer.toolpath.build import compute_toolpath
from slicer.toolpath.candidate_choice import Candidates, choose
from slicer.toolpath.component import Component
from slicer.toolpath.layer_build import split_layers
from slicer.toolpath.line_source import LineSource
from slicer.toolpath.linking import Lifter
from slicer.toolpath.volume import required_volume
from tests.slicer.toolpath.pattern_meshes import disc, rings_with_bridge
from tests.slicer.toolpath.test_build import PROFILE, flat_layer


def chosen(radius: float, inner: float) -> candidate_choice.Choice:
    """The choice on one flat contour-layer annulus (H 0.6 mm, W about 2.3 mm)."""
    v, f = disc(radius, 0.5, inner)
    layer = split_layers(flat_layer(v, f, 0.6))[0]
    cfg = JobConfig().toolpath
    comp = Component(layer, np.arange(len(layer.faces)), Pattern.CONTOUR, cfg, PROFILE)
    surf = LineSource.of(comp.vertices, comp.faces, cfg.fit_bands, False,
                         cfg.boundary_distance, cfg.stripe_field, cfg.fit_ridge)
    required = required_volume(comp.vertices, comp.faces, comp.height_sliced)
    cand = Candidates(comp, cfg, layer.vertices.min(axis=0),
                      Lifter(layer.vertices, np.tile([0.0, 0.0, 1.0], (len(v), 1))), 1.0,
                      required)
    return choose(cand, surf, Pattern.CONTOUR, False, comp.vertices)


def test_a_band_one_width_wide_gets_its_centre_line() -> None:
    """An annulus 2 mm wide (below 1.5 W) holds one line along its middle, its volume
    fitted."""
    c = chosen(13.0, 11.0)
    assert c.fallback == ComponentFallback.CENTRE_LINE and c.used == Pattern.CONTOUR
    assert abs(c.match.rel_error) < 0.01
    pos = c.match.result.waypoints.position[c.match.result.waypoints.extrude]
    assert np.all(np.abs(np.hypot(pos[:, 0], pos[:, 1]) - 12.0) < 0.3)


def test_a_wide_annulus_keeps_its_contours() -> None:
    """An annulus 8 W wide is printed with its layer's contours and matches the volume."""
    c = chosen(30.0, 11.0)
    assert c.used == Pattern.CONTOUR
    assert c.fallback in (ComponentFallback.NONE, ComponentFallback.HOLES_FILLED,
                          ComponentFallback.NO_BAND)
    assert abs(c.match.rel_error) < 0.02


def test_stripe_layer_walls_get_their_centre_line(monkeypatch: pytest.MonkeyPatch) -> None:
    """Two tube walls (about one W thick) joined by a solid bridge, on a stripe layer:
    stripes across the walls are stubs joined by U-turns that lay half the ink, and the
    volume match then spreads the bridge's stripes apart. With the walls printed along
    their middle and stripes on the bridge only, the stripes keep their spacing (p50 47 ->
    2 %, p90 54 -> 33 %), and the wall lines lie on the walls' middle."""
    v, f = rings_with_bridge()
    layers = flat_layer(v, f, 0.6)
    # (full-width joins: narrow ones lay less ink on the stubs, and the stripes everywhere
    # then keep their spacing about as well)
    config = JobConfig().with_overrides(toolpath={"first_pattern": "stripe",
                                                  "narrow_joins": False})
    res = compute_toolpath(layers, config, PROFILE, measure_baselines=False, workers=1)
    monkeypatch.setattr(candidate_choice, "WALL_SHARE", 2.0)  # never: stripes everywhere
    everywhere = compute_toolpath(layers, config, PROFILE, measure_baselines=False, workers=1)
    assert [s["fallback"] for s in res.layer_stats] == [["walls"]]
    assert [s["fallback"] for s in everywhere.layer_stats] == [[""]]
    we, wa = res.report["width_error"]["stripe"], everywhere.report["width_error"]["stripe"]
    assert we["p90"] < wa["p90"] and we["p50"] < 0.1 < wa["p50"]
    assert res.report["connector_volume_fraction"] < everywhere.report["connector_volume_fraction"]
    assert abs(res.report["layer_volume_error"]) < 0.01
    tp = res.toolpath
    outer = tp.extrude & (np.abs(tp.position[:, 0]) > 26.0 + 4.0)  # the walls' far sides
    radius = np.hypot(np.abs(tp.position[outer, 0]) - 26.0, tp.position[outer, 1])
    assert np.all(np.abs(radius - (14.0 - 1.2)) < 0.25)
    assert np.all(tp.pattern[tp.extrude] == Pattern.STRIPE)
