"""Layer-height statistics measured on the layers (area-weighted), not per tet."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from core.stages import Layers
from slicer.config import SlicingConfig
from slicer.field import compute_field
from slicer.field_heights import height_stats
from slicer.heights import FaceHeights, face_heights, initial_layers, outside_profile
from slicer.layers import extract_layers
from slicer.operators import build_operators
from tests.slicer.conftest import box_mesh


def two_triangles(h_small: float, h_large: float) -> Layers:
    """A 1 mm^2-leg triangle with H = h_small and a 2 mm-leg one (4x the area) with h_large."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 0, 0], [7, 0, 0], [5, 2, 0]], float)
    h = np.array([h_small] * 3 + [h_large] * 3)
    return Layers(vertices=v, faces=np.array([[0, 1, 2], [3, 4, 5]], dtype=np.int32),
                  face_layer=np.array([0, 1], dtype=np.int32), vertex_height=h,
                  vertex_direction=np.tile([0.0, 0.0, 1.0], (6, 1)))


def test_statistics_are_weighted_by_layer_area() -> None:
    fh = face_heights(two_triangles(1.0, 0.5))
    assert fh.area == pytest.approx([0.5, 2.0])
    stats = fh.stats()
    assert stats.mean == pytest.approx((0.5 * 1.0 + 2.0 * 0.5) / 2.5)
    assert stats.max == pytest.approx(1.0) and stats.min == pytest.approx(0.5)


def test_outside_profile_counts_area_and_layers() -> None:
    fh = face_heights(two_triangles(1.0, 0.5))
    out = outside_profile(fh, 0.6, 2.0)
    assert out["below"] == pytest.approx(0.8)
    assert out["above"] == 0.0
    assert out["layers"] == 1


def test_no_faces_give_nan_statistics() -> None:
    empty = FaceHeights(np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.int32))
    assert np.isnan(empty.stats().mean)


def test_a_flat_tet_on_a_critical_region_does_not_reach_the_statistics() -> None:
    # A third critical region on a side wall: tets with three vertices on it have grad g near
    # zero and a per-tet "height" many times the target; the layers pass between the regions
    # and keep H within a few targets.
    mesh = box_mesh((3, 3, 6), (6.0, 6.0, 12.0), jitter=0.2, seed=3)
    config = SlicingConfig(layer_height_mm=1.0,
                           critical=("bottom:10", "top:10", "normal:1,0,0:10"))
    result = compute_field(mesh, config)
    assert height_stats(result.operators, result.g, 1.0).stats.max > 10.0
    stats = face_heights(extract_layers(mesh, result, config).layers).stats()
    assert stats.max < 3.5
    assert 0.5 < stats.mean < 1.5


def test_the_initial_field_is_measured_on_its_own_layers() -> None:
    mesh = box_mesh((3, 3, 6), (6.0, 6.0, 12.0), jitter=0.2, seed=3)
    result = compute_field(mesh, SlicingConfig(layer_height_mm=1.0,
                                               critical=("bottom:10", "top:10")))
    base = face_heights(initial_layers(result, 12))
    assert base.layer.max() + 1 == 12  # 12 mm at 1 mm
    assert base.stats().mean == pytest.approx(1.0, rel=0.05)


def test_a_nearly_flat_initial_field_gets_as_many_layers_as_the_final_one() -> None:
    # A g0 flat over most of the part and steep in a corner (a thin plate with two critical
    # faces, issue 21's octagonal pocket): g0's own spacing for a 0.6 mm mean height asked for
    # 7 million layers and ran out of 21 GB; the baseline takes the final layer count.
    mesh = box_mesh((6, 6, 2), (40.0, 30.0, 2.0), jitter=0.1, seed=5)
    ops = build_operators(mesh)
    g0 = (mesh.vertices[:, 0] / 40.0) ** 12 * 1e-3
    assert (g0.max() - g0.min()) / height_stats(ops, g0, 0.6).delta > 1e5
    result = SimpleNamespace(g0=g0, operators=ops)
    layers = initial_layers(result, 3)  # type: ignore[arg-type]
    assert layers.layer_count == 3
    assert np.isfinite(face_heights(layers).stats().mean)


def test_the_histogram_draws_a_field_without_layers_as_such(tmp_path: Path) -> None:
    # a constant harmonic start (trimesh's teapot, repaired) has no layers: no division by a
    # zero weight, a legend line saying so
    from slicer.figures import height_histogram

    path = height_histogram(np.zeros(0), np.zeros(0), np.full(4, 0.6), np.ones(4), 0.6,
                            tmp_path / "h.png")
    assert path.stat().st_size > 1000
