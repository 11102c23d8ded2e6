"""Time law: joint limits never exceeded, toolpath speed kept, slow-downs reported."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from core.stages import Toolpath
from planner.cell import CellConfig
from planner.path_derivatives import window_derivative
from planner.plan import PlanResult, plan
from planner.timing import _scan_limit


def test_scan_limit_equals_the_sequential_recursion() -> None:
    rng = np.random.default_rng(0)
    cap = rng.uniform(0, 10, 200)
    inc = rng.uniform(0, 1, 199)
    x = np.empty(200)
    x[0] = cap[0]
    for k in range(1, 200):
        x[k] = min(cap[k], x[k - 1] + inc[k - 1])
    assert np.allclose(_scan_limit(cap, inc), x)


def _limits_hold(result: PlanResult, cell: CellConfig) -> None:
    tr = result.trajectory
    vmax = np.radians(cell.robot.max_velocity_deg_s)
    amax = np.radians(cell.robot.max_acceleration_deg_s2)
    assert np.all(np.abs(tr.qd) <= vmax * (1 + 1e-9))
    acc = np.abs(np.diff(tr.qd, axis=0)) / np.diff(tr.t)[:, None]
    assert np.all(acc <= amax * (1 + 1e-9))
    assert np.all(np.diff(tr.t) > 0)


def test_limits_never_exceeded(dome_plan: PlanResult, lines_plan: PlanResult,
                               cell: CellConfig) -> None:
    _limits_hold(dome_plan, cell)
    _limits_hold(lines_plan, cell)


def test_joint_rates_integrate_to_the_positions(dome_plan: PlanResult) -> None:
    tr = dome_plan.trajectory
    # trapezoidal integration of the DLS joint rates reproduces the IK positions
    dq = 0.5 * (tr.qd[1:] + tr.qd[:-1]) * np.diff(tr.t)[:, None]
    step = np.diff(tr.q, axis=0)
    scale = np.abs(step).max()
    assert np.percentile(np.abs(dq - step).max(axis=1), 95) < 0.05 * scale


def test_tcp_speed_follows_the_toolpath(dome_plan: PlanResult) -> None:
    tr = dome_plan.trajectory
    v = np.linalg.norm(np.diff(tr.tcp, axis=0), axis=1) / np.diff(tr.t)
    target = dome_plan.samples.speed[:-1]
    ex = tr.extrude[:-1]
    ratio = v[ex] / target[ex]
    assert np.mean(np.abs(ratio - 1.0) < 0.05) > 0.95
    assert dome_plan.report["speed_ratio"]["within_5pct"] > 0.95


def test_slow_joints_force_slower_tcp_and_report_over_deposition(
    lines_tp: Toolpath, cell: CellConfig
) -> None:
    robot = dataclasses.replace(cell.robot, max_velocity_deg_s=(0.5,) * 6,
                                max_acceleration_deg_s2=(5.0,) * 6)
    slow = dataclasses.replace(cell, robot=robot)
    result = plan(lines_tp, slow)
    _limits_hold(result, slow)
    od = result.report["over_deposition"]
    assert od["slowed_steps"] > 10
    assert od["volume_mm3"] > 0 and od["max_local_factor"] > 1.05
    assert result.report["speed_ratio"]["p50"] < 0.95


def test_null_space_motion_only_spins_the_tool() -> None:
    from planner import kinematics as kin
    from planner.timing import _null_vector

    rng = np.random.default_rng(4)
    q = np.radians([170.0, -90.0, 110.0, -110.0, -90.0, 0.0]) + rng.normal(0, 0.2, (20, 6))
    tool = np.eye(4)
    tool[2, 3] = 0.29
    J = kin.jacobian(q, tool)
    a = kin.fk(q, tool)[:, :3, 2]
    n = _null_vector(J, a, np.zeros(len(q)))
    twist = np.einsum("mij,mj->mi", J, n)
    assert np.allclose(twist[:, :3], 0.0, atol=1e-10)  # the TCP stays put
    w = twist[:, 3:]
    assert np.allclose(np.cross(w, a), 0.0, atol=1e-10)  # it turns about the nozzle axis
    assert np.all(np.linalg.norm(w, axis=1) > 0)


def test_last_step_of_each_path_keeps_the_toolpath_speed(lines_plan: PlanResult,
                                                         lines_tp: Toolpath) -> None:
    # the move to the next path runs at the travel speed; the path's own last (extruding)
    # step must not: it deposits at constant C, so it keeps the toolpath speed
    tr, sm = lines_plan.trajectory, lines_plan.samples
    wp = tr.waypoint
    is_wp = wp >= 0
    assert np.allclose(sm.speed[is_wp], lines_tp.speed[wp[is_wp]])
    path = lines_tp.path
    last = np.flatnonzero(np.r_[path[1:] != path[:-1], True])  # last waypoint of each path
    rows = np.flatnonzero(np.isin(wp, last) & is_wp)
    rows = rows[rows > 0]
    assert len(rows) == len(last)
    assert tr.extrude[rows - 1].all()  # the step into the path's last waypoint deposits
    v = np.linalg.norm(tr.tcp[rows] - tr.tcp[rows - 1], axis=1) / (tr.t[rows] - tr.t[rows - 1])
    target = lines_tp.speed[wp[rows]]
    # the job's very last step ends at rest (half speed on average); every other one is exact
    assert np.all(np.abs(v[:-1] / target[:-1] - 1.0) < 0.05)
    assert lines_plan.report["speed_ratio"]["within_5pct"] > 0.97


def test_each_step_keeps_its_joint_speed_whatever_the_rates_say() -> None:
    """A spin of 20 deg at one place (the rates, from the tool's motion, do not see it): the
    time law gives that step time enough for the joint to turn within its limit."""
    from planner.timing import time_law

    M = 40
    s = np.linspace(0.0, 39.0, M)  # mm: 1 mm steps
    tcp = np.column_stack([s, np.zeros(M), np.zeros(M)])
    q = np.zeros((M, 6))
    q[20:, 5] = np.radians(20.0)  # the last joint turns 20 deg between samples 19 and 20
    dq = np.full((M, 6), 1e-4)  # rad/mm: what the rates would say
    vmax, amax = np.radians(np.full(6, 180.0)), np.radians(np.full(6, 800.0))
    timing = time_law(q, dq, tcp, s, np.full(M, 50.0), vmax, amax)
    speed = np.abs(np.diff(q, axis=0)) / np.diff(timing.t)[:, None]
    assert np.all(speed <= vmax + 1e-9)
    assert np.diff(timing.t)[19] >= np.radians(20.0) / vmax[5]


def test_joint_path_curvature_is_taken_over_a_window_not_between_close_samples() -> None:
    # q' steps by 1 at a kink of the joint path between s = 5 and a sample inserted 1 um
    # after it (as the continuity stage inserts them): neighbouring differences see a
    # curvature of ~500 there, the +-0.5 mm window the step spread over 1 mm
    s = np.sort(np.r_[np.arange(0.0, 10.01, 0.5), 5.001])
    y = (s > 5.0005).astype(float)[:, None]
    assert np.abs(np.gradient(y, s, axis=0)).max() > 100.0
    d = window_derivative(y, s, 0.5)
    assert np.abs(d).max() <= 1.0 + 1e-9
    # exact on a quadratic away from the ends (a symmetric window)
    q = (s**2)[:, None]
    inner = (s >= 0.5) & (s <= 9.5)
    assert np.allclose(window_derivative(q, s, 0.5)[inner, 0], 2 * s[inner], atol=0.13)


def test_rates_at_a_junction_come_from_its_depositing_side() -> None:
    from planner.timing import angular_rates

    # a straight line, then a turn about z at 1 rad/mm from sample 5 on (a move)
    s = np.arange(10.0)
    ang = np.where(s > 5, s - 5, 0.0)
    c, sn = np.cos(ang), np.sin(ang)
    R = np.zeros((10, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -sn, sn, c, 1.0
    side = np.zeros(10, dtype=np.int8)
    side[5] = -1  # deposition stops at sample 5
    central = angular_rates(R, s)
    one = angular_rates(R, s, side)
    assert central[5, 2] > 0.4  # the central difference sees half the move's turn
    assert np.allclose(one[5], 0.0)  # the arriving (depositing) step turns nothing
    assert np.allclose(one[np.r_[0:5, 6:10]], central[np.r_[0:5, 6:10]])


def _ramped(tp: Toolpath, peak: float, base: float = 5.0) -> Toolpath:
    """``tp`` (straight lines, waypoints 0.5 mm apart) at ``base`` mm/s, at ``peak`` between
    x = 10.5 and 19.5 mm of each line: the speed ramps over one 0.5 mm segment each way."""
    x = tp.position[:, 0]
    speed = np.where((x > 10.25) & (x < 19.75), peak, base)
    return dataclasses.replace(tp, speed=speed, width=6.57 / (tp.height * speed))


def _kept_on_ramps(result: PlanResult, base: float = 5.0) -> float:
    """Share of the extruding steps at or above 1.1 x ``base`` kept within 5 %."""
    tr, sm = result.trajectory, result.samples
    v = np.linalg.norm(np.diff(tr.tcp, axis=0), axis=1) / np.diff(tr.t)
    target = 0.5 * (sm.speed[:-1] + sm.speed[1:])
    on = tr.extrude[:-1] & (target >= 1.1 * base)
    return float(np.mean(np.abs(v[on] / target[on] - 1.0) <= 0.05))


def test_the_arm_keeps_a_speed_change_at_the_cells_path_acceleration(
        lines_tp: Toolpath, cell: CellConfig) -> None:
    # 5 mm/s -> P over 0.5 mm asks P (P - 5) / 0.5 at the top: P = 12.8 mm/s asks the bundled
    # cell's path acceleration (200 mm/s^2), which the slicer ramps the stripe joins to
    # (core.path_accel); 5 -> 100 mm/s over 0.5 mm asks 19,000 mm/s^2
    a = cell.planning.path_accel_mm_s2
    assert a == pytest.approx(200.0)
    peak = 0.5 * (5.0 + np.sqrt(25.0 + 4.0 * a * 0.5))
    kept = plan(_ramped(lines_tp, peak), cell)
    assert kept.report["path_accel"]["segments_over"] == 0
    assert kept.report["path_accel"]["max_asked_mm_s2"] == pytest.approx(a)
    assert _kept_on_ramps(kept) >= 0.98
    _limits_hold(kept, cell)
    steep = plan(_ramped(lines_tp, 100.0), cell)
    assert steep.report["path_accel"]["segments_over"] == 6  # up and down on each line
    assert _kept_on_ramps(steep) < 0.9
