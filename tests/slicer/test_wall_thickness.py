"""Wall thickness: the inward ray across standing walls, on shapes whose walls are known."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from slicer.mesh_io import Surface
from slicer.wall_thickness import wall_thickness


def _surface(mesh: trimesh.Trimesh) -> Surface:
    return Surface(mesh.vertices, mesh.faces, Path("shape.stl"))


def test_a_standing_slab_measures_its_thickness() -> None:
    """A 40 x 1 x 30 mm slab standing up: almost all its standing-wall area is its two big
    faces, 1 mm apart; the narrow ends measure the 40 mm length."""
    walls = wall_thickness(_surface(trimesh.creation.box(extents=(40.0, 1.0, 30.0))))
    assert walls.quantile(0.5) == pytest.approx(1.0, abs=1e-4)
    ends = 2 * 30.0 * 1.0 / (2 * 40.0 * 30.0 + 2 * 30.0 * 1.0)
    assert walls.share_below(1.5) == pytest.approx(1.0 - ends, abs=0.02)
    assert np.all(np.isfinite(walls.thickness))


def test_a_flat_plate_is_spanned_by_layers_not_lines() -> None:
    """A 40 x 30 x 1 mm plate lying flat: its big faces are not standing walls; its rim
    measures the plate across (30-40 mm)."""
    walls = wall_thickness(_surface(trimesh.creation.box(extents=(40.0, 30.0, 1.0))))
    assert walls.share_below(5.0) == 0.0
    assert walls.quantile(0.0) == pytest.approx(30.0, abs=1e-4)


def test_a_tube_wall_and_scaling() -> None:
    tube = trimesh.creation.annulus(r_min=14.5, r_max=15.0, height=40.0, sections=64)
    walls = wall_thickness(_surface(tube))
    # the chord across a 0.5 mm wall of radius 15 mm, faceted at 64 sections
    assert walls.quantile(0.5) == pytest.approx(0.5, rel=0.05)
    doubled = walls.scaled(2.0)
    assert doubled.quantile(0.5) == pytest.approx(2 * walls.quantile(0.5))
    assert doubled.size_mm == pytest.approx(2 * walls.size_mm)


def test_seeded_and_no_standing_walls() -> None:
    box = _surface(trimesh.creation.box(extents=(10.0, 10.0, 10.0)))
    assert np.array_equal(wall_thickness(box).thickness, wall_thickness(box).thickness)
    flat = trimesh.creation.cone(radius=20.0, height=2.0, sections=64)  # slopes < 45 deg
    walls = wall_thickness(_surface(flat))
    assert len(walls.thickness) == 0 and walls.share_below(1.0) == 0.0
