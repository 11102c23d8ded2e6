"""A layer component's path: the stripe joins' speed ramps follow the path accelerations of
the cell the job is for (``Component``'s ``accel``, passed down from ``mesp slice --cell``),
and the process values of the joins are computed once per join point."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from core.path_accel import PathAccel
from core.stages import Layers, Pattern
from slicer.config import JobConfig
from slicer.extrusion import load_profile
from slicer.toolpath.build import compute_toolpath
from slicer.toolpath.component import Component, SurfaceValues
from slicer.toolpath.linking import LinkedPath
from tests.slicer.toolpath.pattern_meshes import disc

PROFILE = load_profile("ecoflex-0030")


def _join_width_ratio(accel: PathAccel | None) -> NDArray[np.float64]:
    """Width over W(H) at every extruding waypoint of one flat stripe layer (a 16 mm disc at
    H = 0.6 mm) built with ``accel``."""
    v, f = disc(16.0, 0.8, jitter=0.2)
    cfg = JobConfig().with_overrides(toolpath={"first_pattern": "stripe"})
    layers = Layers(v, f, np.zeros(len(f), np.int32), np.full(len(v), 0.6),
                    np.tile([0.0, 0.0, 1.0], (len(v), 1)))
    tp = compute_toolpath(layers, cfg, PROFILE, measure_baselines=False, workers=1,
                          accel=accel).toolpath
    assert np.all(tp.pattern == Pattern.STRIPE)
    ext = tp.extrude
    return np.asarray(tp.width[ext] / (PROFILE.rate_mm3_s
                                       / (tp.height[ext] * PROFILE.speed_at(tp.height[ext]))))


def test_the_joins_ramp_within_the_given_cells_path_acceleration() -> None:
    bundled = _join_width_ratio(None)
    assert np.array_equal(bundled, _join_width_ratio(PathAccel.bundled()))
    # the bundled cell's arm reaches the joins' speed: they print at down to half width
    assert bundled.min() < 0.55 and np.mean(bundled < 0.75) > 0.05
    # a cell whose arm barely accelerates cannot speed the joins up: they print near full
    # width (W = C / (H v) at the speed it reaches)
    slow = _join_width_ratio(PathAccel(1.0, 0.01))
    assert slow.min() > 0.7 and np.mean(slow < 0.75) < 0.01


def test_the_joins_values_are_computed_once_and_equal_computed_afresh(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The narrowed path keeps the values of the points it had (``narrow_joins_indexed``'s
    index): only its added points are computed, and every point's H, v, W and normal equal
    those computed for the whole path."""
    from slicer.toolpath import component as component_module

    asked: list[int] = []  # points of every values_at call
    calls: list[tuple[int, int]] = []  # narrowed paths: (points computed, points added)
    seen: list[tuple[Component, LinkedPath, NDArray[np.float64] | None, SurfaceValues]] = []
    surface_values, values_at = Component._surface_values, Component.values_at

    def count(self: Component, face: NDArray[np.int32], bary: NDArray[np.float64],
              scale: NDArray[np.float64] | None = None) -> tuple[NDArray[np.float64], ...]:
        asked.append(len(face))
        return values_at(self, face, bary, scale)

    def spy(self: Component, linked: LinkedPath, scale: NDArray[np.float64] | None,
            known: tuple[SurfaceValues, NDArray[np.int64]] | None = None) -> SurfaceValues:
        before = len(asked)
        out = surface_values(self, linked, scale, known)
        if known is not None:
            calls.append((sum(asked[before:]), len(linked.points) - len(known[1])))
            seen.append((self, linked, scale, out))
        return out

    monkeypatch.setattr(component_module.Component, "values_at", count)
    monkeypatch.setattr(component_module.Component, "_surface_values", spy)
    _join_width_ratio(None)
    assert seen, "no stripe joins were narrowed"
    # the narrowed path: only its added points are computed again
    assert all(computed <= added for computed, added in calls), calls
    assert sum(computed for computed, _ in calls) > 0
    monkeypatch.undo()
    for comp, linked, scale, values in seen:
        fresh = surface_values(comp, linked, scale)
        for a, b in zip(values, fresh, strict=True):
            assert np.array_equal(a, b)
