"""Cell description: bundled default, overrides, errors naming the key."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from planner.cell import CellConfig, load_cell


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


def test_numbers_are_finite_and_within_the_cell_ranges(tmp_path: Path) -> None:
    path = tmp_path / "cell.toml"
    for text, needle in (("[tank]\nyaw_deg = nan\n", "yaw_deg' is nan"),
                         ("[robot]\nbase_xyz_mm = [inf, 0.0, 0.0]\n", "finite"),
                         ("[planning]\nmax_step_mm = 1e-6\n", r"outside 0\.05 to 100"),
                         ("[planning]\nspin_steps = 100000000\n", "outside 4 to 720"),
                         ("[[tool.parts]]\nname = \"x\"\nshape = \"box\"\n"
                          "center_mm = [0.0, 0.0, 0.0]\nsize_mm = [1e9, 1.0, 1.0]\n",
                          "size_mm")):
        path.write_text(text)
        with pytest.raises(InputError, match=needle):
            load_cell(path)
