"""Analytic clearances: against brute force and against MuJoCo's mj_geomDistance."""

from __future__ import annotations

import numpy as np

from planner.cell import CellConfig
from planner.collision import (
    Box,
    CollisionModel,
    _box_sdf,
    segment_box_distance,
    segment_segment_distance,
)


def _brute_segment_box(p0: np.ndarray, p1: np.ndarray, box: Box) -> np.ndarray:
    t = np.linspace(0.0, 1.0, 4001)
    pts = p0[:, None, :] + t[None, :, None] * (p1 - p0)[:, None, :]
    return _box_sdf(pts, box).min(axis=1)


def test_segment_box_distance_matches_brute_force() -> None:
    rng = np.random.default_rng(0)
    a = rng.normal(size=(3, 3))
    R, _ = np.linalg.qr(a)
    box = Box("b", np.array([0.1, -0.2, 0.3]), R, np.array([0.2, 0.05, 0.1]))
    p0 = rng.uniform(-0.6, 0.6, (200, 3)) + box.center
    p1 = rng.uniform(-0.6, 0.6, (200, 3)) + box.center
    d = segment_box_distance(p0, p1, box, iters=30)
    assert np.allclose(d, _brute_segment_box(p0, p1, box), atol=2e-4)


def test_box_sdf_inside_is_negative() -> None:
    box = Box("b", np.zeros(3), np.eye(3), np.array([1.0, 2.0, 3.0]))
    assert np.isclose(_box_sdf(np.zeros(3), box), -1.0)
    assert np.isclose(_box_sdf(np.array([2.0, 0.0, 0.0]), box), 1.0)
    assert np.isclose(_box_sdf(np.array([2.0, 3.0, 0.0]), box), np.sqrt(2.0))


def test_segment_segment_distance_matches_brute_force() -> None:
    rng = np.random.default_rng(1)
    p0, p1, q0, q1 = (rng.normal(size=(30, 3)) for _ in range(4))
    q1[:5] = q0[:5] + 2.0 * (p1[:5] - p0[:5])  # parallel cases
    d = segment_segment_distance(p0, p1, q0, q1)
    t = np.linspace(0.0, 1.0, 301)
    P = p0[:, None, :] + t[None, :, None] * (p1 - p0)[:, None, :]
    Q = q0[:, None, :] + t[None, :, None] * (q1 - q0)[:, None, :]
    brute = np.linalg.norm(P[:, :, None, :] - Q[:, None, :, :], axis=-1).min(axis=(1, 2))
    assert np.all(d <= brute + 1e-12)
    assert np.allclose(d, brute, atol=1.5e-2)


def test_clearance_agrees_with_mujoco_geom_distance(cell: CellConfig) -> None:
    from sim.twin import Twin

    model = CollisionModel(cell)
    twin = Twin(cell)
    rng = np.random.default_rng(2)
    home = np.radians(cell.robot.home_deg)
    q = home + rng.normal(0.0, 0.25, (6, 6))
    a, b = model.segments(q)
    names = [c.name for c in model.capsules]
    box = next(bx for bx in model.boxes if bx.name == "tank_wall_-x")
    for link in ("forearm", "wrist_1", "wrist_2"):
        ci = names.index(link)
        ours = (segment_box_distance(a[:, ci], b[:, ci], box, 30) - model.capsules[ci].radius)
        for k in range(len(q)):
            theirs = twin.geom_distance(q[k], link, "tank_wall_-x", distmax=10.0)
            assert abs(ours[k] * 1000.0 - theirs) < 0.05


def test_self_collision_is_detected(cell: CellConfig) -> None:
    model = CollisionModel(cell)
    folded = np.radians([0.0, -90.0, 175.0, 0.0, 90.0, 0.0])  # elbow closed on itself
    home = np.radians(cell.robot.home_deg)
    c = model.clearance(np.stack([home, folded]))
    assert c.distance[0] > 0
    assert c.distance[1] < 0


def test_a_raised_base_stands_on_a_pedestal_the_arm_must_clear(cell: CellConfig) -> None:
    import dataclasses

    from planner.collision import cell_boxes

    boxes = {b.name: b for b in cell_boxes(cell)}
    base_z = cell.robot.base_xyz_mm[2]
    assert base_z > 0 and "pedestal" in boxes
    # from the table top up to the base, whose frame is the boxes' frame (m)
    ped = boxes["pedestal"]
    assert np.isclose(ped.center[2] + ped.half[2], 0.0)
    assert np.isclose(2 * ped.half[2] * 1000.0, base_z - 0.0)
    names = CollisionModel(cell).names
    assert "shoulder vs pedestal" not in names and "forearm vs pedestal" in names
    flat = dataclasses.replace(cell, robot=dataclasses.replace(cell.robot,
                                                               base_xyz_mm=(0.0, 0.0, 0.0)))
    assert "pedestal" not in {b.name for b in cell_boxes(flat)}
