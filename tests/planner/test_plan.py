"""The whole plan: trajectory file, targets reached, report keys, the `mesp plan` command."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from core.report import read_report
from core.stages import Toolpath
from mesp_cell.cli import main
from planner import kinematics as kin
from planner.cell import CellConfig
from planner.plan import PlanResult, plan
from planner.refusal import bends
from planner.trajectory import Trajectory
from tests.planner import synthetic
from tests.planner.synthetic import make_toolpath


def test_trajectory_reaches_every_waypoint(dome_plan: PlanResult, dome_tp: Toolpath) -> None:
    tr = dome_plan.trajectory
    wp = tr.waypoint >= 0
    assert np.array_equal(tr.waypoint[wp], np.arange(len(dome_tp)))
    target = dome_tp.position @ tr.model_T[:3, :3].T + tr.model_T[:3, 3]
    assert np.allclose(tr.tcp[wp], target, atol=1e-6)
    tool = tr.tool_T.copy()
    tool[:3, 3] /= 1000.0
    T = kin.fk(tr.q, tool)
    assert np.allclose(T[:, :3, 3] * 1000.0, tr.tcp, atol=1e-6)
    normal = dome_tp.normal @ tr.model_T[:3, :3].T
    # the nozzle axis is -normal where no tilt was needed
    assert np.allclose(T[wp, :3, 2], -normal, atol=1e-6)
    # between samples the TCP never jumps more than max_step_mm
    assert np.linalg.norm(np.diff(tr.tcp, axis=0), axis=1).max() <= 2.0 + 1e-9


def test_report_has_the_plan_keys(dome_plan: PlanResult) -> None:
    rep = dome_plan.report
    for key in ("duration_s", "min_clearance_mm", "alpha_deg", "joint_margin_deg",
                "speed_ratio", "unreachable", "over_deposition", "status"):
        assert key in rep
    assert rep["status"] == "ok"
    assert rep["min_clearance_mm"] >= 3.0
    assert np.isclose(rep["duration_s"], dome_plan.trajectory.t[-1])


def test_trajectory_round_trip(dome_plan: PlanResult, tmp_path: Path) -> None:
    dome_plan.trajectory.save(tmp_path)
    back = Trajectory.load(tmp_path)
    for name, arr in dome_plan.trajectory.arrays().items():
        assert np.array_equal(arr, getattr(back, name))
    with np.load(tmp_path / "trajectory.npz") as f:
        assert f["q"].dtype == np.float64 and f["waypoint"].dtype == np.int32
        assert f["extrude"].dtype == np.bool_ and f["model_T"].shape == (4, 4)


def test_mesp_plan_command(lines_tp: Toolpath, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    lines_tp.save(tmp_path)
    assert main(["plan", str(tmp_path), "--quiet"]) == 0
    tr = Trajectory.load(tmp_path)
    assert (tr.waypoint >= 0).sum() == len(lines_tp)
    rep = read_report(tmp_path)["plan"]
    assert rep["unreachable"]["count"] == 0
    assert (tmp_path / "figures" / "plan_joints.png").is_file()
    assert (tmp_path / "figures" / "plan_alpha.png").is_file()
    assert (tmp_path / "figures" / "plan_clearance.png").is_file()
    assert (tmp_path / "figures" / "plan_margin.png").is_file()


def test_mesp_plan_user_errors(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    assert main(["plan", str(tmp_path / "missing")]) == 2
    assert main(["plan", str(tmp_path)]) == 2  # no toolpath.npz
    err = capsys.readouterr().err
    assert "toolpath.npz" in err and "Traceback" not in err


def test_mesp_plan_fails_with_one_line_when_the_plan_is_not_executable(
        cell: CellConfig, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from tests.planner.test_orientation import _wall_case

    # waypoints reachable with a tilt, but the pose above the first one is not: blocked entry
    _, tp = _wall_case(cell)
    tp.save(tmp_path)
    cell_file = tmp_path / "near_wall.toml"
    cell_file.write_text("[robot]\nbase_xyz_mm = [0.0, 0.0, 0.0]\n[placement]\n"
                         "offset_mm = [80.0, 0.0, 10.0]\nyaw_deg = 0.0\nsearch = false\n")
    code = main(["plan", str(tmp_path), "--cell", str(cell_file), "--quiet", "--no-figures"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 3
    assert len(err) == 1 and err[0].startswith("mesp: error: the plan cannot be executed")
    assert "unreachable entry" in err[0] and "Traceback" not in err[0]
    assert (tmp_path / "trajectory.npz").is_file()  # kept for inspection


def _alpha_at_both_ends(result: PlanResult) -> np.ndarray:
    """alpha (deg) of every depositing step, against its chord, at its first and last sample."""
    tr = result.trajectory
    tool = tr.tool_T.copy()
    tool[:3, 3] /= 1000.0
    axis = kin.fk(tr.q, tool)[:, :3, 2]
    chord = np.diff(tr.tcp, axis=0)
    length = np.linalg.norm(chord, axis=1)
    dep = tr.extrude[:-1] & (length > 1e-6)
    c = chord[dep] / length[dep, None]
    ends = np.concatenate([np.einsum("ij,ij->i", axis[:-1][dep], c),
                           np.einsum("ij,ij->i", axis[1:][dep], c)])
    return np.degrees(np.arccos(np.clip(ends, -1.0, 1.0)))


def test_alpha_holds_along_a_step_that_climbs_out_of_the_layer(cell: CellConfig) -> None:
    # a flat line whose one step climbs 0.6 mm over 0.9 mm (a connection to another height):
    # against that step's direction the nozzle on -normal sits at alpha 124 deg. Both ends of
    # the step must be tilted, not only the waypoint where the step starts (the central
    # difference at the far end averages the climb with the flat step after it)
    x = np.arange(0.0, 20.0, 0.9)
    z = np.where(x > 10.0, 0.6, 0.0)
    pos = np.column_stack([x, np.zeros_like(x), z])
    tp = synthetic.make_toolpath(pos, np.tile([0.0, 0.0, 1.0], (len(x), 1)),
                                 np.zeros(len(x)))
    result = plan(tp, cell)
    assert result.status == "ok"
    alpha = _alpha_at_both_ends(result)
    assert alpha.max() > 100.0  # the climb needed a tilt
    assert alpha.min() >= cell.planning.alpha_min_deg - 1e-6
    assert alpha.max() <= cell.planning.alpha_max_deg + 1e-6


def test_a_path_bending_up_out_of_its_layer_is_refused_with_a_fix(
        cell: CellConfig, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # a flat path that steps 1.5 mm straight up (along its own normal) and goes on: no
    # nozzle axis is within alpha [70, 110] of both the flat steps and the vertical one
    x = np.arange(0.0, 10.01, 0.5)
    flat = np.column_stack([x, np.zeros_like(x), np.full_like(x, 5.0)])
    up = np.array([[10.0, 0.0, 5.75], [10.0, 0.0, 6.5]])
    on = np.column_stack([10.5 + x, np.zeros_like(x), np.full_like(x, 6.5)])
    pos = np.concatenate([flat, up, on])
    tp = make_toolpath(pos, np.tile([0.0, 0.0, 1.0], (len(pos), 1)),
                       np.zeros(len(pos), np.int32))
    tp.save(tmp_path)
    # no placement can help: refused before the search, on every waypoint, with the cause,
    # the layer and the alpha range that would serve it (checked by the same test)
    code = main(["plan", str(tmp_path), "--quiet", "--no-figures"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert "waypoint 20 (layer 0, at 10.0, 0.0, 5.0 mm)" in err[0]
    assert "bends against its layer" in err[0] and "re-slice" in err[0]
    assert "tried tray: refused (bend)" in err[0]
    # the bent waypoints are left out of the search: the rest is reachable, and said so
    assert "(the rest is reachable: " in err[0] and "besides" not in err[0]
    assert "planning options tried: lean_max_deg = 60: 3 waypoints still bent" in err[0]
    found = bends(tp, cell)
    assert list(found.waypoint) == [20, 21, 22]
    half = float(np.ceil(found.needed_deg.max()))
    wide = replace(cell, planning=replace(cell.planning, alpha_min_deg=90 - half,
                                          alpha_max_deg=90 + half))
    assert len(bends(tp, wide).waypoint) == 0  # the suggested range serves them
