"""[model] scale_to_mm / mesp slice --scale-to: a model scaled uniformly to a printable size."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import trimesh

from slicer.config import ModelConfig
from slicer.mesh_io import load_surface, load_tet_mesh, write_tet_mesh
from tests.slicer.conftest import box_mesh


def test_a_surface_is_scaled_to_its_largest_extent(tmp_path: Path) -> None:
    path = tmp_path / "part.stl"
    trimesh.creation.box(extents=(2.0, 1.0, 0.5)).export(path)
    surface = load_surface(path, ModelConfig(scale_to_mm=60.0))
    extent = surface.vertices.max(axis=0) - surface.vertices.min(axis=0)
    assert extent == pytest.approx([60.0, 30.0, 15.0])
    assert any("scaled by 30" in n for n in surface.notes)


def test_units_apply_before_the_scale(tmp_path: Path) -> None:
    path = tmp_path / "part.stl"
    trimesh.creation.box(extents=(2.0, 1.0, 0.5)).export(path)
    inches = load_surface(path, ModelConfig(units="in", scale_to_mm=60.0))
    assert float(np.ptp(inches.vertices[:, 0])) == pytest.approx(60.0)


def test_a_tet_mesh_is_scaled_too(tmp_path: Path) -> None:
    path = write_tet_mesh(box_mesh(), tmp_path / "box.vtu")
    mesh = load_tet_mesh(path, ModelConfig(scale_to_mm=40.0))
    assert float(np.ptp(mesh.vertices, axis=0).max()) == pytest.approx(40.0)


@pytest.mark.parametrize("value", [-1.0, 0.5, 5000.0, math.nan])
def test_a_scale_outside_the_size_range_is_refused(value: float) -> None:
    with pytest.raises(ValueError, match="scale_to_mm"):
        ModelConfig(scale_to_mm=value)


def test_off_keeps_the_file_size(tmp_path: Path) -> None:
    path = tmp_path / "part.stl"
    trimesh.creation.box(extents=(20.0, 10.0, 5.0)).export(path)
    surface = load_surface(path, ModelConfig())
    assert float(np.ptp(surface.vertices[:, 0])) == pytest.approx(20.0)
    assert not any("scaled" in n for n in surface.notes)
