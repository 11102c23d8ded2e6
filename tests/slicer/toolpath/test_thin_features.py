"""Features thinner than the narrowest line: found on a flat strip, the size that prints
them, and the refusal's message."""

from __future__ import annotations

import numpy as np
import pytest

from slicer.config import JobConfig
from slicer.extrusion import load_profile
from slicer.toolpath.build import compute_toolpath
from slicer.toolpath.thin_features import (
    EXCESS_LIMIT,
    THINNEST,
    ThinFeatures,
    ThinWallsError,
    suggested_size,
)
from tests.slicer.toolpath.test_build import flat_layer
from tests.slicer.toolpath.test_medial import strip

PROFILE = load_profile("ecoflex-0030")


def test_a_strip_a_quarter_line_wide_is_marked_with_its_width_and_excess() -> None:
    """A 60 mm strip 0.25 W wide: its one line cannot be narrower than 0.5 W, so it lays
    about twice the strip's volume; the strip is found, its width read back from the ink."""
    w = float(PROFILE.width(np.array([1.0]))[0])
    layers = flat_layer(*strip(60.0, 0.25 * w, 0.6), 1.0)
    res = compute_toolpath(layers, JobConfig(), PROFILE, measure_baselines=False, workers=1)
    thin = res.thin
    assert thin is not None and len(thin.layer) == 1
    q = float(thin.deposited_mm3[0] / thin.required_mm3[0])
    assert 1.7 < q < 2.3  # 0.5 W printed on a 0.25 W strip
    assert thin.typical_width_mm() == pytest.approx(0.25 * w, rel=0.15)
    assert thin.typical_line_mm() == pytest.approx(THINNEST * w, rel=0.05)
    # at 2x the size the strip is 0.5 W wide: its line fits
    model = float(thin.required_mm3.sum())
    assert 1.0 < thin.scale_for(model) <= q


def test_a_strip_wider_than_the_narrowest_line_is_not_marked() -> None:
    w = float(PROFILE.width(np.array([1.0]))[0])
    layers = flat_layer(*strip(60.0, 0.8 * w, 0.6), 1.0)
    res = compute_toolpath(layers, JobConfig(), PROFILE, measure_baselines=False, workers=1)
    assert res.thin is not None and len(res.thin.layer) == 0


def _features(q: list[float], req: list[float]) -> ThinFeatures:
    n = len(q)
    return ThinFeatures(layer=np.arange(n, dtype=np.int64), required_mm3=np.array(req),
                        deposited_mm3=np.array(q) * np.array(req), line_mm=np.ones(n))


def test_the_scale_brings_the_excess_to_the_limit() -> None:
    """excess(s) / model(s) = sum req (q - s)+ / (s V): one component of 10 mm^3 at q = 4
    in a 100 mm^3 model: s with 10 (4 - s) / (100 s) at the limit; the suggested size aims
    at half the limit (the layers are cut anew at the new size)."""
    thin = _features([4.0], [10.0])
    s = thin.scale_for(100.0, EXCESS_LIMIT)
    assert 10.0 * (4.0 - s) / (s * 100.0) == pytest.approx(EXCESS_LIMIT, rel=1e-6)
    assert thin.scale_for(100.0) > s
    # within the limit already: no scaling
    assert _features([1.5], [0.5]).scale_for(100.0) == 1.0
    assert suggested_size(40.0, 1.0) == 40.0 and suggested_size(40.0, 2.13) == 100.0


def test_the_summary_marks_each_layer_with_its_excess() -> None:
    thin = ThinFeatures(layer=np.array([3, 3, 7]), required_mm3=np.array([1.0, 2.0, 1.0]),
                        deposited_mm3=np.array([2.0, 3.0, 1.5]), line_mm=np.full(3, 1.1))
    section = thin.summary(model_mm3=50.0, size_mm=40.0)
    assert section["layers"] == [[3, 2.0], [7, 0.5]]
    assert section["excess_mm3"] == pytest.approx(2.5)
    assert section["excess_share"] == pytest.approx(0.05)
    assert section["fits_at_size_mm"] > 40.0


def test_extra_ink_within_the_layers_slab_is_not_counted() -> None:
    """A layer that only grazes the top of its slab (a part ending mid-slab): slivers whose
    lines lay 9 x their own volume but less than the slab holds count nothing; a layer that
    lays beyond its slab counts what lies beyond it."""
    thin = ThinFeatures(layer=np.array([1, 4]), required_mm3=np.array([280.0, 5.0]),
                        deposited_mm3=np.array([300.0, 45.0]), line_mm=np.full(2, 1.8))
    laid = np.array([600.0, 300.0, 200.0, 200.0, 45.0])
    slab = np.array([600.0, 290.0, 200.0, 200.0, 75.0])
    counted = thin.within_slabs(laid, slab)
    assert counted.excess_mm3 == pytest.approx(10.0)
    section = counted.summary(model_mm3=1340.0, size_mm=40.0)
    assert section["layers"] == [[1, 10.0]] and section["components"] == 1


def test_the_refusal_names_the_wall_the_line_the_layers_and_a_size() -> None:
    section = {"too_thin": {"wall_mm": 0.2, "line_mm": 1.15, "size_mm": 40.0,
                            "excess_share": 4.7, "layers": [[0, 5.5], [66, 4.5]],
                            "fits_at_size_mm": 230.0}}
    exc = ThinWallsError("round.stl", section, (40.0, 40.0, 40.0))
    text = exc.one_line()
    assert text.startswith("round.stl has walls about 0.20 mm thick at its 40 mm size")
    assert "(1.15 mm)" in text and "2 layer(s) (0-66" in text and "+470.0%" in text
    assert "--scale-to 230" in text and 'thin_walls = "thicken"' in text
    assert exc.bbox_mm == (230.0, 230.0, 230.0)
    checked = exc.with_cell("230 mm tall, it would stand out of the gel (80 mm)").one_line()
    assert "at --scale-to 230, where its walls would print, 230 mm tall" in checked
    assert "finer nozzle" in checked
