"""Entry into and exit from the gel: home -> above -> plunge along the nozzle axis, and back."""

from __future__ import annotations

import numpy as np
import pytest

from core.stages import Toolpath
from planner import kinematics as kin
from planner.cell import CellConfig
from planner.entry import PLUNGE, RETRACT, TRANSFER, safe_heights, safe_move, time_move
from planner.placement import fit_gel
from planner.plan import PlanResult, plan
from planner.reach import OK, Reach
from planner.status import PlanStatus
from planner.timing import time_law

TOOL_PARTS = ("holder", "extruder", "nozzle_collar")


def _reach(cell: CellConfig, tp: Toolpath) -> Reach:
    return Reach(fit_gel(cell, tp))


def _gel_top(reach: Reach) -> float:
    cell = reach.cell
    return float((np.linalg.inv(cell.robot.base_T) @ cell.tank.floor_T)[2, 3]
                 + cell.tank.gel_fill_mm)


def _lowest_tool_part_mm(reach: Reach, q: np.ndarray) -> np.ndarray:
    """Lowest point (S,) mm of the holder, extruder and collar capsules."""
    col = reach.collision
    a, b = col.segments(q)
    idx = [i for i, c in enumerate(col.capsules) if c.name in TOOL_PARTS]
    r = np.array([col.capsules[i].radius for i in idx])
    z = np.minimum(a[:, idx, 2], b[:, idx, 2]) - r
    return z.min(axis=1) * 1000.0


def _parts(tr_wp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    wp = np.flatnonzero(tr_wp >= 0)
    rows = np.arange(len(tr_wp))
    return rows[: wp[0]], rows[wp[-1] + 1:]


def test_trajectory_begins_and_ends_at_home(dome_plan: PlanResult, cell: CellConfig) -> None:
    tr = dome_plan.trajectory
    home = np.radians(cell.robot.home_deg)
    assert np.allclose(tr.q[0], home, atol=1e-9) and np.allclose(tr.q[-1], home, atol=1e-9)
    assert np.allclose(tr.qd[[0, -1]], 0.0)
    entry, leave = _parts(tr.waypoint)
    assert len(entry) > 10 and len(leave) > 10
    assert not tr.extrude[entry].any() and not tr.extrude[leave].any()
    assert dome_plan.status == "ok"
    assert dome_plan.report["entry"]["status"] == "ok"
    assert dome_plan.report["exit"]["status"] == "ok"
    # the cell's home: nozzle vertical, tip above the tank rim, on the planner's IK branch
    T = kin.fk(home, Reach(cell).tool_m)
    rim = cell.tank.floor_center_mm[2] + cell.tank.inner_size_mm[2]
    assert T[2, 2] < -0.9999 and T[2, 3] * 1000.0 > rim + 50.0


def test_entry_and_exit_are_clear_and_only_the_shaft_enters_the_gel(
    dome_plan: PlanResult, dome_tp: Toolpath, cell: CellConfig
) -> None:
    reach = _reach(cell, dome_tp)
    tr = dome_plan.trajectory
    entry, leave = _parts(tr.waypoint)
    rows = np.concatenate([entry, leave])
    c = reach.collision.clearance(tr.q[rows])
    assert c.distance.min() >= cell.planning.clearance_mm
    # holder, extruder and collar stay above the gel surface on every sample of the job
    assert _lowest_tool_part_mm(reach, tr.q).min() >= _gel_top(reach)
    # below the gel surface the tip moves only along the first waypoint's nozzle axis
    first = entry[-1] + 1
    T = kin.fk(tr.q[entry], reach.tool_m)
    a0 = kin.fk(tr.q[first], reach.tool_m)[:3, 2]
    p0 = tr.tcp[first]
    low = tr.tcp[entry, 2] < _gel_top(reach) + 1.0
    assert low.any()
    d = tr.tcp[entry][low] - p0
    off_axis = d - np.outer(d @ a0, a0)
    assert np.abs(off_axis).max() < 0.05
    assert np.allclose(T[low, :3, 2], a0, atol=1e-6)


def test_time_law_limits_hold_on_entry_and_exit(dome_plan: PlanResult,
                                                cell: CellConfig) -> None:
    tr = dome_plan.trajectory
    entry, leave = _parts(tr.waypoint)
    vmax = np.radians(cell.robot.max_velocity_deg_s)
    amax = np.radians(cell.robot.max_acceleration_deg_s2)
    for rows in (np.r_[entry, entry[-1] + 1], np.r_[leave[0] - 1, leave]):
        assert np.all(np.abs(tr.qd[rows]) <= vmax * 1.0001)
        dt = np.diff(tr.t[rows])
        acc = np.abs(np.diff(tr.qd[rows], axis=0)) / dt[:, None]
        assert np.all(acc <= amax * 1.0001)
        # no joint moves faster than its velocity limit between samples either
        assert np.all(np.abs(np.diff(tr.q[rows], axis=0)) / dt[:, None] <= vmax * 1.05)
    # along the nozzle axis (in and near the gel) the tip moves at most at the travel speed
    z_safe = dome_plan.report["entry"]["safe_z_mm"]
    step = np.linalg.norm(np.diff(tr.tcp[entry], axis=0), axis=1) / np.diff(tr.t[entry])
    near = tr.tcp[entry][1:, 2] < z_safe - 1.0
    assert near.any()
    assert np.all(step[near] <= cell.planning.travel_speed_mm_s * 1.02)


def test_blocked_entry_is_reported(cell: CellConfig) -> None:
    from tests.planner.test_orientation import _wall_case

    # a layer leaning 25 deg towards the wall, placed near it, the robot on the table (no
    # pedestal): the waypoints are reachable with a tilt, but the pose above the first one on
    # its nozzle axis is out of reach
    wall_cell, tp = _wall_case(cell)
    result = plan(tp, wall_cell)
    assert result.report["unreachable"]["count"] == 0
    assert result.status == PlanStatus.ENTRY_BLOCKED
    assert result.message.startswith("unreachable entry: ")
    assert "\n" not in result.message and "placement" in result.message  # one line, a fix
    assert result.report["entry"]["status"] != "ok"
    assert np.all(np.diff(result.trajectory.t) > 0)  # still a well-formed trajectory


def test_resume_approach_from_a_stop_in_the_gel(dome_plan: PlanResult, dome_tp: Toolpath,
                                                cell: CellConfig) -> None:
    """The robot stopped mid-job; it resumes at an earlier sample: out along its axis,
    above the gel, in along the target's axis, never closer than the clearance."""
    reach = _reach(cell, dome_tp)
    tr = dome_plan.trajectory
    wp = np.flatnonzero(tr.waypoint >= 0)
    here, there = tr.q[wp[len(wp) * 3 // 4]], tr.q[wp[len(wp) // 4]]
    move = safe_move(reach, here, there, safe_heights(reach), tolerate_start=True)
    assert move.ok, move.reason
    assert np.allclose(move.q[0], here) and np.allclose(move.q[-1], there)
    assert set(np.unique(move.segment)) == {RETRACT, TRANSFER, PLUNGE}
    assert np.all(move.status == OK)
    assert reach.collision.clearance(move.q).distance.min() >= cell.planning.clearance_mm
    assert _lowest_tool_part_mm(reach, move.q).min() >= _gel_top(reach)
    # the transfer happens above the gel with the whole nozzle out of it
    transfer = move.segment == TRANSFER
    assert move.tcp[transfer, 2].min() >= _gel_top(reach)
    # the retract leaves along the nozzle axis of the stop pose
    T = kin.fk(move.q[move.segment == RETRACT], reach.tool_m)
    a = T[0, :3, 2]
    d = move.tcp[move.segment == RETRACT] - move.tcp[0]
    assert np.abs(d - np.outer(d @ a, a)).max() < 0.05
    timing = time_move(reach, move)
    assert timing.status == "ok" and np.all(np.diff(timing.t) > 0)
    assert np.all(np.abs(timing.qd) <= np.radians(cell.robot.max_velocity_deg_s) * 1.0001)
    assert np.allclose(timing.qd[move.stop], 0.0)


def test_a_move_to_where_the_robot_is_is_empty(cell: CellConfig) -> None:
    reach = Reach(cell)
    move = safe_move(reach, reach.home, reach.home, safe_heights(reach))
    assert move.ok and len(move.q) == 1


@pytest.mark.parametrize("k", [3, 7])
def test_time_law_rests_at_stop_samples(k: int) -> None:
    M = 12
    s = np.linspace(0.0, 22.0, M)
    q = np.outer(s / 100.0, np.ones(6))
    dq = np.full((M, 6), 0.01)
    tcp = np.stack([s, np.zeros(M), np.zeros(M)], axis=1)
    stop = np.zeros(M, dtype=bool)
    stop[k] = True
    tm = time_law(q, dq, tcp, s, np.full(M, 10.0), np.full(6, 3.0), np.full(6, 7.0), stop=stop)
    assert tm.status == "ok"
    assert np.allclose(tm.qd[k], 0.0) and np.all(np.abs(tm.qd[k + 1]) > 0)
