"""The acceleration a toolpath may ask for: the cell's, less where the printing direction
turns (core.path_accel)."""

from __future__ import annotations

import numpy as np
import pytest

from core.path_accel import PathAccel, bundled_path_accel, bundled_turn_accel, path_accel
from planner.cell import load_cell


def test_the_bundled_values_come_from_the_cell_file() -> None:
    planning = load_cell().planning
    assert bundled_path_accel() == planning.path_accel_mm_s2 > 0
    assert bundled_turn_accel() == planning.path_turn_accel_rad_s2 > 0
    assert PathAccel.bundled() == planning.path_accel


def test_a_cells_values_are_what_the_slicer_takes() -> None:
    planning = load_cell().planning.__class__(path_accel_mm_s2=50.0,
                                              path_turn_accel_rad_s2=1.5)
    assert planning.path_accel == PathAccel(50.0, 1.5)
    with pytest.raises(ValueError):
        PathAccel(0.0, 1.0)


def test_a_turning_direction_lowers_the_acceleration() -> None:
    # a nozzle accelerating at a along a path turning k rad/mm turns the tool at k a
    # rad/s^2: at most R / k, and the straight path's a where the direction keeps
    rate = np.array([0.0, 0.01, 0.02, 0.1, 1.0])
    a = path_accel(rate, 200.0, 4.0)
    assert a == pytest.approx([200.0, 200.0, 200.0, 40.0, 4.0])
    assert np.all(a * rate <= 4.0 + 1e-12)
    with pytest.raises(ValueError):
        load_cell().planning.__class__(path_turn_accel_rad_s2=0.0)
