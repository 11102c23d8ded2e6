"""The executed trajectory checked against every limit: a breach on one sample is found."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from core.stages import Toolpath
from planner import kinematics as kin
from planner import plan as plan_module
from planner.cell import CellConfig
from planner.orientation import Orientation
from planner.placement import fit_gel
from planner.plan import PlanResult, plan
from planner.reach import Reach
from planner.status import MESSAGES, PlanStatus
from planner.trajectory import Trajectory
from planner.verify import verify


def _check(result: PlanResult, traj: Trajectory, tp: Toolpath, cell: CellConfig
           ) -> list[PlanStatus]:
    """The statuses ``verify`` finds on ``traj`` (planned speeds of ``result``)."""
    reach = Reach(fit_gel(cell, tp))
    return [b.status for b in verify(traj, result.samples.speed, reach).breaches]


def test_a_good_plan_verifies(lines_plan: PlanResult, lines_tp: Toolpath,
                              cell: CellConfig) -> None:
    assert lines_plan.status == PlanStatus.OK
    rep = lines_plan.report["verified"]
    assert rep["ok"] and rep["breaches"] == []
    assert cell.planning.alpha_min_deg <= rep["alpha_deg"][0] <= rep["alpha_deg"][1] \
        <= cell.planning.alpha_max_deg
    assert rep["min_clearance_mm"] >= cell.planning.clearance_mm
    assert rep["joint_speed_fraction"] <= 1.0 and rep["tcp_speed_ratio"] <= 1.0 + 1e-3


def test_one_sample_off_alpha_is_a_breach(lines_plan: PlanResult, lines_tp: Toolpath,
                                          cell: CellConfig) -> None:
    traj = lines_plan.trajectory
    i = int(np.flatnonzero(traj.extrude & (traj.waypoint >= 0))[10])
    q = traj.q.copy()
    q[i, 4] += np.radians(25.0)  # wrist 2 tips the nozzle 25 deg at one sample
    bad = replace(traj, q=q)
    found = verify(bad, lines_plan.samples.speed, Reach(fit_gel(cell, lines_tp)))
    alpha = [b for b in found.breaches if b.status == PlanStatus.ALPHA]
    assert alpha and alpha[0].sample in (i - 1, i)
    assert alpha[0].worst < cell.planning.alpha_min_deg or \
        alpha[0].worst > cell.planning.alpha_max_deg


def test_too_fast_is_a_breach_of_joint_and_tcp_speed(lines_plan: PlanResult,
                                                     lines_tp: Toolpath,
                                                     cell: CellConfig) -> None:
    traj = lines_plan.trajectory
    fast = replace(traj, t=traj.t / 5.0)
    found = _check(lines_plan, fast, lines_tp, cell)
    assert PlanStatus.TCP_SPEED in found and PlanStatus.JOINT_SPEED in found


def test_a_sample_in_the_wall_is_a_clearance_breach(lines_plan: PlanResult,
                                                    lines_tp: Toolpath,
                                                    cell: CellConfig) -> None:
    traj = lines_plan.trajectory
    q = traj.q.copy()
    q[len(q) // 2, 1] += np.radians(40.0)  # the shoulder drops the arm into the tank
    found = _check(lines_plan, replace(traj, q=q), lines_tp, cell)
    assert PlanStatus.CLEARANCE in found


def test_a_plan_whose_executed_sample_breaks_alpha_is_not_ok(
        cell: CellConfig, lines_tp: Toolpath, monkeypatch: pytest.MonkeyPatch) -> None:
    # the orientation stage says every sample is fine, but one pose it hands on tips the
    # nozzle out of the alpha range: the verification of what is executed must refuse it
    real = plan_module.choose

    def off_by_one(reach: Reach, tcp: np.ndarray, normal: np.ndarray, tangent: np.ndarray,
                   extrude: np.ndarray, **kwargs: object) -> Orientation:
        o = real(reach, tcp, normal, tangent, extrude, **kwargs)  # type: ignore[arg-type]
        i = int(np.flatnonzero(extrude)[len(tcp) // 3])
        # the same tip, the nozzle turned 30 deg towards the motion: alpha 60 deg
        turn = Rotation.from_rotvec(np.radians(30.0) * np.cross(o.axis[i], tangent[i]))
        R = kin.fk(o.q[i:i + 1], reach.tool_m)[0, :3, :3]
        q = o.q.copy()
        q[i] = reach.solve(tcp[i:i + 1], (turn.as_matrix() @ R)[None], o.q[i])[0]
        return replace(o, q=q)

    monkeypatch.setattr(plan_module, "choose", off_by_one)
    result = plan(lines_tp, cell)
    assert result.status != PlanStatus.OK  # the continuity stage sees the swing already
    # with nothing between the stages and the trajectory but the verification:
    monkeypatch.setattr(plan_module, "_continuous", lambda reach, s, o: (
        s, o, {"tolerance_mm": 0.05, "steps_split": 0, "samples_inserted": 0,
               "worst_swing_mm": 0.0}))
    result = plan(lines_tp, cell)
    assert result.status == PlanStatus.ALPHA
    assert result.report["status"] == "alpha out of range"
    assert result.message.startswith(MESSAGES[PlanStatus.ALPHA])
    assert "waypoint" in result.message and "layer 0" in result.message


def test_every_status_has_a_message() -> None:
    assert set(MESSAGES) == set(PlanStatus)
