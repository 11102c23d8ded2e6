"""The slicing pipeline end to end on a tiny tet mesh: flushing of exposed filaments."""

from __future__ import annotations

import json
from pathlib import Path

import meshio
import numpy as np
import pytest

from core.stages import Toolpath
from slicer.config import load_job
from slicer.extrusion import load_profile
from slicer.pipeline import slice_model
from slicer.toolpath.flush import filament_height
from tests.slicer.conftest import box_mesh


@pytest.fixture(scope="module")
def sliced(tmp_path_factory: pytest.TempPathFactory) -> dict[bool, Path]:
    """A 16 x 16 x 4 mm planar box sliced with and without flushing."""
    root = tmp_path_factory.mktemp("pipeline")
    mesh = box_mesh(n=(8, 8, 2), size=(16.0, 16.0, 4.0))
    model = root / "box.vtu"
    meshio.write(model, meshio.Mesh(mesh.vertices, [("tetra", mesh.tets)]))
    out = {}
    for flush in (True, False):
        job = load_job().with_overrides(
            slicing={"layer_height_mm": 1.0, "critical": ["bottom:10", "top:10"],
                     "planar": True},
            toolpath={"flush": flush})
        out[flush] = root / f"flush_{flush}"
        slice_model(model, out[flush], job)
    return out


def test_flush_moves_exposed_waypoints_along_their_normal_within_the_bulge(
        sliced: dict[bool, Path]) -> None:
    flushed, plain = Toolpath.load(sliced[True]), Toolpath.load(sliced[False])
    assert len(flushed) == len(plain)
    move = flushed.position - plain.position
    dist = np.linalg.norm(move, axis=1)
    moved = dist > 1e-6
    assert moved.any()
    assert not moved[~plain.extrude].any()  # travel moves stay
    # along the printing direction only, by at most (h_f - H) / 2
    along = np.einsum("ij,ij->i", move, plain.normal)
    np.testing.assert_allclose(np.abs(along[moved]), dist[moved], rtol=1e-6, atol=1e-9)
    # h_f at each waypoint's speed, area-consistent (stripes print at varying speeds)
    h_f = filament_height(plain, load_profile("ecoflex-0030"))[moved]
    assert np.all(dist[moved] <= 0.5 * (h_f - plain.height[moved]) + 1e-6)
    # a planar box: only the first layer (moved up) and the last (moved down) are exposed
    layers = np.unique(plain.layer[moved])
    assert set(layers.tolist()) <= {int(plain.layer.min()), int(plain.layer.max())}
    first = plain.layer == plain.layer.min()
    assert np.all(along[moved & first] > 0) and np.all(along[moved & ~first] < 0)
    # the ink is unchanged: same speeds, widths and heights
    np.testing.assert_array_equal(flushed.speed, plain.speed)
    np.testing.assert_array_equal(flushed.width, plain.width)


def test_flush_is_reported_only_when_on(sliced: dict[bool, Path]) -> None:
    on = json.loads((sliced[True] / "report.json").read_text())["toolpath"]
    off = json.loads((sliced[False] / "report.json").read_text())["toolpath"]
    assert on["flush"]["moved"] > 0 and "flush" not in off


def test_slab_volumes_are_reported_per_layer(sliced: dict[bool, Path]) -> None:
    """Planar 1 mm layers of a 16 x 16 x 4 box: each layer's slab is 256 mm^3, the slabs add
    up to the solid, and the integral of H over each layer agrees with its slab."""
    report = json.loads((sliced[True] / "report.json").read_text())["toolpath"]
    slab = report["slab_volume"]
    assert slab["slab_sum_mm3"] == pytest.approx(16.0 * 16.0 * 4.0, rel=1e-6)
    per_layer = [entry["slab_mm3"] for entry in report["per_layer"]]
    assert np.allclose(per_layer, 256.0, rtol=1e-6)
    assert slab["layer_rel_error_p90"] < 0.01
    # planar layers of a box: first-order H is exact, nothing to match
    scale = json.loads((sliced[True] / "report.json").read_text())["slicing"]["height_slab_scale"]
    assert [scale["min"], scale["max"]] == pytest.approx([1.0, 1.0], abs=1e-6)
    assert scale["layers_beyond_1pct"] == [] and scale["at_limit"] == 0


def test_thin_walls_are_refused_even_where_other_layers_make_up_the_volume() -> None:
    """Walls laying 2 % of the model in extra ink on layer 1 while layer 0 holds 2 % less
    than its slab (the octagonal pocket: ribs under the narrowest line, the top slab
    grazed): the whole volume is exact, the walls still print wider than the model. Refused
    as any part with that much extra ink is (before: printed, the two errors cancelling in
    the sum); printed with ``thin_walls = "thicken"``."""
    from types import SimpleNamespace
    from typing import Any

    from slicer.pipeline import _too_thin
    from slicer.toolpath.thin_features import ThinFeatures, ThinWallsError

    thin = ThinFeatures(np.array([1]), np.array([100.0]), np.array([120.0]), np.array([1.2]))
    result: Any = SimpleNamespace(thin=thin)
    surface: Any = SimpleNamespace(volume_mm3=1000.0, bbox_mm=(40.0, 30.0, 3.0),
                              source="/models/ribs.stl")

    def report() -> dict[str, Any]:
        return {"deposited_volume_mm3": 1000.0,
                "per_layer": [{"layer": 0, "deposited_mm3": 880.0},
                              {"layer": 1, "deposited_mm3": 120.0}]}

    slabs = np.array([900.0, 100.0])
    for walls in ("refuse", "thicken"):
        job = load_job().with_overrides(toolpath={"thin_walls": walls})
        section = report()
        if walls == "refuse":
            with pytest.raises(ThinWallsError, match=r"ribs\.stl has walls about 1\.00 mm"):
                _too_thin(result, section, job, surface, slabs)
        else:
            _too_thin(result, section, job, surface, slabs)
        assert section["too_thin"]["excess_share"] == pytest.approx(0.02)
