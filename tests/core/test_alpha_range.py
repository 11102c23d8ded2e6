"""The cell's printing-angle range sets the slicer's step limits (core.alpha_range)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.alpha_range import AlphaRange
from core.stages import Toolpath
from planner.cell import load_cell
from slicer.toolpath.relief import relieve_bends


def test_the_bundled_range_comes_from_the_cell_file() -> None:
    bundled = AlphaRange.bundled()
    assert bundled == load_cell().planning.alpha_range == AlphaRange(70.0, 110.0)
    assert bundled.step_elevation_deg == 20.0 and bundled.flush_step_deg == pytest.approx(14.0)
    assert AlphaRange(80.0, 120.0).step_elevation_deg == 10.0  # the tighter side
    with pytest.raises(ValueError):
        AlphaRange(95.0, 110.0)


def test_a_narrower_cell_range_relieves_gentler_bends(tmp_path: Path) -> None:
    n = 20
    z = np.zeros(n)
    z[10] = 0.12  # one waypoint kinked out of the layer: steps of 13.5 deg up, then down
    tp = Toolpath(position=np.column_stack([0.5 * np.arange(n), np.zeros(n), z]),
                  normal=np.tile([0.0, 0.0, 1.0], (n, 1)), layer=np.zeros(n, np.int32),
                  path=np.zeros(n, np.int32), height=np.full(n, 0.7), width=np.full(n, 2.0),
                  speed=np.full(n, 10.0), extrude=np.ones(n, bool), pattern=np.ones(n, np.int8))
    _, wide = relieve_bends(tp)  # the bundled [70, 110]: 13.5 deg steps are printable
    assert len(wide.moved) == 0
    cell = tmp_path / "narrow.toml"
    cell.write_text("[planning]\nalpha_min_deg = 82.0\nalpha_max_deg = 98.0\n")
    _, narrow = relieve_bends(tp, load_cell(cell).planning.alpha_range)  # 8 deg steps at most
    assert list(narrow.moved) == [10] and narrow.left == 0
