"""Cell description: bundled default, overrides, errors naming the key."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from planner.cell import CellConfig, load_cell
from slicer.errors import InputError


def test_default_cell_is_valid(cell: CellConfig) -> None:
    assert len(cell.tool.parts) >= 2
    assert cell.robot.max_velocity_deg_s == (180.0,) * 6
    T = cell.tool.tool_T
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3))
    assert cell.tank.gel_fill_mm <= cell.tank.inner_size_mm[2]


def test_override_merges_with_default(tmp_path: Path) -> None:
    f = tmp_path / "cell.toml"
    f.write_text("[tank]\ngel_fill_mm = 80.0\n")
    cell = load_cell(f)
    assert cell.tank.gel_fill_mm == 80.0
    assert cell.tank.inner_size_mm == load_cell().tank.inner_size_mm


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("[robot]\nhome_deg = [0, 0, 0]\n", "home_deg"),
        ("[tank]\nwall_mm = 'thick'\n", "cell.tank.wall_mm"),
        ("[tool]\nnozle_length_mm = 3.0\n", "cell.tool.nozle_length_mm"),
        ("[robot]\nhome_deg = [0, 0, 500, 0, 0, 0]\n", "home_deg"),
        ("[planning]\nalpha_min_deg = 95.0\n", "alpha"),
        ("[planning]\nupright_max_deg = 60.0\n", "upright_max_deg"),
    ],
)
def test_bad_values_name_the_key(tmp_path: Path, text: str, needle: str) -> None:
    f = tmp_path / "cell.toml"
    f.write_text(text)
    with pytest.raises(InputError) as err:
        load_cell(f)
    assert needle in str(err.value)


def test_missing_file_is_input_error(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="does not exist"):
        load_cell(tmp_path / "nope.toml")
