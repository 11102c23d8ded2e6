"""Between two samples the robot moves linearly in joint space: the tip must stay on the path."""

from __future__ import annotations

import numpy as np

from planner import kinematics as kin
from planner.cell import CellConfig
from planner.continuity import SWING_TOL_MM, subdivide, swing
from planner.plan import PlanResult
from planner.reach import Reach

# Two configurations of a real plan (a dome's rim, nozzle tilted towards the robot, the wrist
# centre near the base axis): tips 0.73 mm apart, tool poses 6 deg apart, joints up to 41 deg
NEAR_SINGULAR = np.radians([[165.6, -135.0, 165.0, -155.5, -91.4, 146.5],
                            [136.0, -172.8, 165.5, -114.4, -70.0, 124.4]])


def test_a_small_step_far_from_singularities_does_not_swing(cell: CellConfig) -> None:
    reach = Reach(cell)
    q = reach.home + np.radians([[0.0] * 6, [0.1, -0.1, 0.1, 0.03, -0.03, 0.1]])
    tip = kin.fk(q, reach.tool_m)[:, :3, 3] * 1000.0
    assert 1.0 < np.linalg.norm(tip[1] - tip[0]) < 2.0  # mm: a sample step
    assert swing(q, reach.tool_m)[0] < 0.1 * SWING_TOL_MM


def test_a_step_next_to_a_singularity_is_split_until_the_tip_stays_on_it(
        cell: CellConfig) -> None:
    reach = Reach(cell)
    q = NEAR_SINGULAR
    assert swing(q, reach.tool_m)[0] > 5.0  # mm: the tip would sweep off the path
    sub = subdivide(q, reach.solve, reach.tool_m)
    assert sub.worst_mm <= SWING_TOL_MM
    assert np.all(sub.step == 0) and np.all(np.diff(sub.fraction) > 0)
    full = np.concatenate([q[:1], sub.q, q[1:]])
    assert swing(full, reach.tool_m).max() <= SWING_TOL_MM
    # every inserted sample lies on the straight step, at its fraction, with a tool rotation
    # between the two ends'
    T = kin.fk(full, reach.tool_m)
    tip = T[:, :3, 3] * 1000.0
    expected = tip[0] + sub.fraction[:, None] * (tip[-1] - tip[0])
    assert np.allclose(tip[1:-1], expected, atol=1e-6)
    total = np.arccos(np.clip((np.trace(T[0, :3, :3].T @ T[-1, :3, :3]) - 1) / 2, -1, 1))
    part = np.arccos(np.clip((np.trace(np.einsum("ji,kjl->kil", T[0, :3, :3],
                                                 T[1:-1, :3, :3]), axis1=1, axis2=2) - 1) / 2,
                             -1, 1))
    assert np.allclose(part, sub.fraction * total, atol=1e-6)


def test_nothing_to_split_on_a_smooth_path(cell: CellConfig) -> None:
    reach = Reach(cell)
    q = reach.home + np.outer(np.linspace(0, 1, 20), np.radians([2.0, -1.0, 1.5, 0.5, 1.0, 3.0]))
    sub = subdivide(q, reach.solve, reach.tool_m)
    assert len(sub.step) == 0 and sub.worst_mm == 0.0


def test_a_plan_keeps_the_tip_on_the_path_and_the_joints_within_limits(
        dome_plan: PlanResult, cell: CellConfig) -> None:
    """What the streamer executes: q linear between samples, |dq| / dt per step."""
    tr = dome_plan.trajectory
    reach = Reach(cell)
    part = dome_plan.samples.waypoint >= 0
    first, last = np.flatnonzero(part)[[0, -1]]
    assert swing(tr.q[first:last + 1], reach.tool_m).max() <= SWING_TOL_MM
    speed = np.abs(np.diff(tr.q, axis=0)) / np.diff(tr.t)[:, None]
    assert np.all(speed <= np.radians(cell.robot.max_velocity_deg_s) + 1e-9)
    assert "continuity" in dome_plan.report


def test_samples_failing_between_waypoints_are_named_with_their_reason(
        cell: CellConfig) -> None:
    from planner.orientation import Orientation
    from planner.plan_report import between_status as _between_status
    from planner.reach import COLLISION, OK
    from planner.samples import Samples

    reach = Reach(cell)
    M = 6
    z = np.zeros((M, 3))
    samples = Samples(tcp=z, normal=z, tangent=z,
                      waypoint=np.array([0, -1, -1, 1, -1, 2], np.int32),
                      extrude=np.ones(M, bool), speed=np.ones(M), height=np.ones(M), arrive=z)
    status = np.full(M, OK, np.int8)
    status[[2, 4]] = COLLISION
    pair = np.full(M, -1, np.int32)
    pair[2] = 0
    orient = Orientation(q=np.zeros((M, 6)), axis=z, psi=np.zeros(M), tilt=np.zeros(M),
                         lean=np.zeros(M), status=status, pair=pair, clearance=np.zeros(M))
    text = _between_status(reach, samples, orient, np.array([2, 4]))
    assert text.startswith("2 samples between waypoints unreachable, first after waypoint 0")
    assert f"collision of {reach.collision.names[0]}" in text
