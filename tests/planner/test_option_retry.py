"""Planning options the planner re-tries before it names them as a fix (option_retry.py)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from core.configtools import read_toml
from core.stages import Toolpath
from mesp_cell.cli import main
from planner.cell import CellConfig, load_cell
from planner.option_retry import as_cell, retry
from planner.plan import plan
from planner.refusal import bends
from planner.status import Cause, PlanStatus
from tests.planner.synthetic import make_toolpath


def _climb_then_turn() -> Toolpath:
    """Flat along +x, one step climbing 35 deg, then flat along +y: at the corner no tilt
    keeps alpha on both the climbing arriving step and the level leaving one; a lean of at
    least 15 deg about the leaving step does."""
    x = np.arange(0.0, 5.01, 0.5)
    flat = np.column_stack([x, np.zeros_like(x), np.full_like(x, 5.0)])
    corner = np.array([[5.0 + 0.5 * np.cos(np.radians(35)), 0.0,
                        5.0 + 0.5 * np.sin(np.radians(35))]])
    y = np.arange(0.5, 5.01, 0.5)
    on = np.column_stack([np.full_like(y, corner[0, 0]), y, np.full_like(y, corner[0, 2])])
    pos = np.concatenate([flat, corner, on])
    return make_toolpath(pos, np.tile([0.0, 0.0, 1.0], (len(pos), 1)),
                         np.zeros(len(pos), np.int32))


@pytest.mark.slow
def test_a_lean_the_cell_forbids_is_retried_and_plans(cell: CellConfig) -> None:
    tp = _climb_then_turn()
    stiff = replace(cell, planning=replace(cell.planning, lean_max_deg=0.0))
    assert list(bends(tp, stiff).waypoint) == [11]  # the corner
    assert len(bends(tp, cell).waypoint) == 0
    found = retry(tp, stiff, Cause.BEND)
    assert found.option == {"lean_max_deg": 60.0}
    assert found.tried[-1] == "lean_max_deg = 60: ok"
    # the option is only a fix because the planner checked it: the plan is ok with it
    fixed = replace(stiff, planning=replace(stiff.planning, **found.option))
    assert plan(tp, fixed).status == PlanStatus.OK


def test_nothing_is_retried_where_the_cell_already_allows_it(cell: CellConfig) -> None:
    wide = replace(cell, planning=replace(cell.planning, lean_max_deg=60.0))
    assert retry(_climb_then_turn(), wide, Cause.BEND) == ((None, ()))
    assert retry(_climb_then_turn(), cell, Cause.DOWNWARD) == ((None, ()))  # no option helps


def test_the_fix_file_keeps_the_users_cell() -> None:
    user = {"tank": {"gel_fill_mm": 60.0}, "planning": {"clearance_mm": 4.0}}
    out = as_cell(user, {"lean_max_deg": 60.0})
    assert out == {"tank": {"gel_fill_mm": 60.0},
                   "planning": {"clearance_mm": 4.0, "lean_max_deg": 60.0}}


@pytest.mark.slow
def test_mesp_plan_names_the_checked_option_and_it_works_when_followed(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    job = tmp_path / "job"
    _climb_then_turn().save(job)
    stiff = tmp_path / "stiff.toml"
    stiff.write_text("[planning]\nlean_max_deg = 0.0\n")
    code = main(["plan", str(job), "--cell", str(stiff), "--quiet", "--no-figures"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert "waypoint 11 (layer 0" in err[0] and "bends against its layer" in err[0]
    assert "cell_checked.toml" in err[0] and "checked: the job plans ok with it" in err[0]
    written = job / "cell_checked.toml"
    assert read_toml(written) == {"planning": {"lean_max_deg": 60.0}}
    assert load_cell(written).planning.lean_max_deg == 60.0
    # followed as written, the job plans
    assert main(["plan", str(job), "--cell", str(written), "--quiet", "--no-figures"]) == 0
