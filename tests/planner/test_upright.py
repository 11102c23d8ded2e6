"""The nozzle turns towards vertical where following the normal would near a singularity."""

from __future__ import annotations

import numpy as np

from planner.cell import CellConfig
from planner.nozzle_axis import alpha_of
from planner.plan import plan
from planner.reach import Reach
from planner.upright import COMFORT, turn_towards, upright
from tests.planner import synthetic

UP = np.array([0.0, 0.0, 1.0])


def _far_side_stroke(lean_deg: float, n: int = 60) -> tuple[np.ndarray, ...]:
    """A stroke along y at the tank's far side, 30 mm above its floor (base frame, mm), its
    printing direction leaning ``lean_deg`` towards the robot (the socket's rounded bottom)."""
    tcp = np.column_stack([np.full(n, 512.0), np.linspace(-15.0, 15.0, n), np.full(n, -113.0)])
    a = np.radians(lean_deg)
    normal = np.tile([-np.sin(a), 0.0, np.cos(a)], (n, 1))
    tangent = np.tile([0.0, 1.0, 0.0], (n, 1))
    return tcp, normal, tangent, np.ones(n, dtype=bool)


def test_turn_towards_turns_by_the_angle_and_stops_at_up() -> None:
    rng = np.random.default_rng(3)
    n = rng.normal(size=(200, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    angle = rng.uniform(0.0, np.pi, 200)
    out = turn_towards(n, UP, angle)
    assert np.allclose(np.linalg.norm(out, axis=1), 1.0)
    theta = np.arccos(np.clip(n @ UP, -1, 1))
    turned = np.arccos(np.clip(np.einsum("ij,ij->i", out, n), -1, 1))
    assert np.allclose(turned, np.minimum(angle, theta), atol=1e-6)
    left = np.arccos(np.clip(out @ UP, -1, 1))
    assert np.allclose(left, theta - np.minimum(angle, theta), atol=1e-6)
    # the turn stays in the plane of the normal and up
    assert np.allclose(np.einsum("ij,ij->i", out, np.cross(n, UP)), 0.0, atol=1e-9)


def test_a_pose_next_to_the_shoulder_singularity_is_uprighted_until_comfortable(
        cell: CellConfig) -> None:
    reach = Reach(cell)
    tcp, normal, tangent, extrude = _far_side_stroke(40.0)
    up = upright(reach, tcp, normal, tangent, extrude)
    assert up.margin.max() < COMFORT  # on the normal the wrist is near the base axis
    assert np.all(up.angle > 0) and np.degrees(up.angle.max()) <= cell.planning.upright_max_deg
    after = upright(reach, tcp, up.normal, tangent, extrude)
    assert after.margin.min() >= COMFORT and np.all(after.angle == 0)
    # turned in the plane of motion's normal: alpha stays 90 deg on a stroke along y
    assert np.allclose(np.degrees(alpha_of(-up.normal, tangent)), 90.0)


def test_a_comfortable_pose_keeps_its_normal(cell: CellConfig) -> None:
    reach = Reach(cell)
    tcp, normal, tangent, extrude = _far_side_stroke(5.0)
    up = upright(reach, tcp, normal, tangent, extrude)
    assert up.margin.min() >= COMFORT
    assert np.all(up.angle == 0) and np.array_equal(up.normal, normal)


def test_the_turn_ramps_in_and_out_along_the_path(cell: CellConfig) -> None:
    reach = Reach(cell)
    tcp, normal, tangent, extrude = _far_side_stroke(5.0, 60)
    steep = _far_side_stroke(40.0, 60)[1]
    normal[20:40] = steep[20:40]  # a steep stretch in the middle of a comfortable stroke
    up = upright(reach, tcp, normal, tangent, extrude)
    assert np.all(up.angle[20:40] > 0)
    assert np.abs(np.diff(up.angle)).max() <= np.radians(1.0) + 1e-9
    assert up.angle[0] == 0 and up.angle[-1] == 0


def test_alpha_bounds_the_turn_of_an_extruding_sample(cell: CellConfig) -> None:
    reach = Reach(cell)
    tcp, normal, _, extrude = _far_side_stroke(40.0)
    # moving down the layer towards the robot, the nozzle already trailing at alpha 75 deg:
    # uprighting turns it in the plane of motion, so alpha drops by the turn
    a = np.radians(40.0)
    down = np.array([-np.cos(a), 0.0, -np.sin(a)])
    tangent = np.tile(np.cos(np.radians(75.0)) * -normal[0] + np.sin(np.radians(75.0)) * down,
                      (len(tcp), 1))
    assert np.allclose(np.degrees(alpha_of(-normal, tangent)), 75.0)
    printing = upright(reach, tcp, normal, tangent, extrude)
    alpha = np.degrees(alpha_of(-printing.normal, tangent))
    assert np.all(alpha >= cell.planning.alpha_min_deg - 1e-6)
    assert np.degrees(printing.angle.max()) == 5.0  # 10 deg would comfort, but alpha 65
    travel = upright(reach, tcp, normal, tangent, ~extrude)  # a travel move has no bound
    assert np.degrees(travel.angle.max()) == 10.0
    assert upright(reach, tcp, travel.normal, tangent, ~extrude).margin.min() >= COMFORT


def test_a_plan_keeps_the_wrist_away_from_the_base_axis_under_a_bowl(cell: CellConfig) -> None:
    # a cup's rounded bottom: on the ring's far side the normal leans 40 deg towards the robot
    tp = synthetic.rings(40.0, [0.0, 100.0], [40.0, 0.0], step=1.0)
    result = plan(tp, cell)
    rep = result.report["upright"]
    assert result.status == "ok"
    assert rep["margin_on_normal_min"] < COMFORT <= rep["margin_min"]
    assert 0 < rep["samples"] and 0 < rep["max_deg"] <= cell.planning.upright_max_deg
    # where nothing is uprighted the nozzle follows the normal
    tr = result.trajectory
    top = (tr.waypoint >= np.flatnonzero(tp.path == 1)[0]) & tr.extrude
    assert np.allclose(tr.alpha[top], 90.0, atol=1.0)
