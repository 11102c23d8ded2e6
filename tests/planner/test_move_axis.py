"""Moves between paths: the printing direction eased from one path's end to the next's start."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import planner.plan as plan_module
from core.stages import Toolpath
from planner.cell import CellConfig
from planner.move_axis import SETTLE_MM, ease_moves, moves, slerp, smootherstep
from planner.samples import Samples
from tests.planner.synthetic import make_toolpath


def test_smootherstep_has_no_rate_and_no_acceleration_at_its_ends() -> None:
    u = np.linspace(0.0, 1.0, 2001)
    e = smootherstep(u)
    assert e[0] == 0.0 and e[-1] == 1.0 and np.all(np.diff(e) >= 0)
    d1 = np.gradient(e, u)
    d2 = np.gradient(d1, u)
    assert abs(d1[0]) < 1e-5 and abs(d1[-1]) < 1e-5
    # the analytic rate 30 u^2 (1 - u)^2 and acceleration 60 u (1 - u) (1 - 2u) against
    # finite differences: both vanish at the ends
    inner = u[2:-2]
    assert np.allclose(d1[2:-2], 30 * inner**2 * (1 - inner) ** 2, atol=1e-5)
    assert np.allclose(d2[2:-2], 60 * inner * (1 - inner) * (1 - 2 * inner), atol=1e-3)
    assert np.all(smootherstep(np.array([-1.0, 2.0])) == [0.0, 1.0])


def test_slerp_turns_at_a_constant_rate_on_the_great_circle() -> None:
    a = np.tile([1.0, 0.0, 0.0], (5, 1))
    b = np.tile([0.0, 1.0, 0.0], (5, 1))
    w = np.linspace(0.0, 1.0, 5)
    out = slerp(a, b, w)
    assert np.allclose(np.linalg.norm(out, axis=1), 1.0)
    assert np.allclose(out[0], a[0]) and np.allclose(out[-1], b[0])
    assert np.allclose(np.arctan2(out[:, 1], out[:, 0]), w * np.pi / 2)
    flip = slerp(a[:1], -a[:1], np.array([0.5]))  # opposite: any perpendicular axis
    assert np.isclose(np.linalg.norm(flip), 1.0) and abs(flip[0] @ a[0]) < 1e-9


def test_moves_pair_each_stop_with_the_next_start() -> None:
    ex = np.array([1, 1, 1, 0, 0, 0, 1, 1, 0, 0], dtype=bool)
    # deposition stops at sample 3 (step 2 -> 3 deposits, 3 -> 4 does not), starts at 6;
    # the stop at 8 has no start after it (the job's end)
    a, b = moves(ex)
    assert a.tolist() == [3] and b.tolist() == [6]
    a0, b0 = moves(np.ones(4, dtype=bool))
    assert len(a0) == len(b0) == 0


def _samples(normal: np.ndarray, extrude: np.ndarray, step: float = 0.25) -> Samples:
    M = len(normal)
    tcp = np.column_stack([np.arange(M) * step, np.zeros(M), np.zeros(M)])
    tangent = np.tile([1.0, 0.0, 0.0], (M, 1))
    return Samples(tcp, normal, tangent, np.arange(M, dtype=np.int32), extrude,
                   np.full(M, 10.0), np.full(M, 0.5), np.zeros((M, 3)))


def test_a_move_turns_in_its_middle_and_holds_the_ends() -> None:
    # 5 depositing samples at +30 deg, a 6 mm move (24 steps) whose own normals jump to
    # vertical, 5 depositing samples at -30 deg (about y)
    a30 = np.radians(30.0)
    M = 5 + 23 + 5
    normal = np.tile([0.0, 0.0, 1.0], (M, 1))
    normal[:5] = [np.sin(a30), 0.0, np.cos(a30)]
    normal[-5:] = [-np.sin(a30), 0.0, np.cos(a30)]
    extrude = np.zeros(M, dtype=bool)
    extrude[:4] = True  # deposition stops at sample 4
    extrude[-5:-1] = True  # and starts at sample M - 5
    eased = ease_moves(_samples(normal, extrude))
    n = eased.normal
    on = np.r_[np.arange(5), np.arange(M - 5, M)]
    assert np.allclose(n[on], normal[on])  # depositing samples keep their directions
    angle = np.degrees(np.arctan2(n[:, 0], n[:, 2]))
    assert np.all(np.diff(angle[4:M - 4]) <= 1e-9)  # one monotone turn from +30 to -30
    s = np.arange(M) * 0.25
    held = (np.abs(s - s[4]) <= SETTLE_MM - 1e-9) | (np.abs(s - s[M - 5]) <= SETTLE_MM - 1e-9)
    assert np.allclose(np.abs(angle[held]), 30.0)  # held near where deposition stops/starts
    assert np.isclose(angle[(4 + M - 5) // 2], 0.0, atol=1e-6)  # half way in the middle
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)


def _two_paths(tilt_deg: float = 30.0, length: float = 20.0, step: float = 0.5,
               gap: float = 4.0, lift: float = 0.8) -> Toolpath:
    """Two depositing lines on layers tilted +-tilt about y, joined by a move whose own
    waypoints (lifted, as the slicer's) carry vertical normals: the lift-off step turns the
    printing direction by ``tilt_deg`` in under a millimetre."""
    a = np.radians(tilt_deg)
    y = np.arange(0.0, length + 1e-9, step)
    first = np.column_stack([np.zeros_like(y), y, np.zeros_like(y)])
    second = np.column_stack([np.full_like(y, gap), y[::-1], np.zeros_like(y)])
    move = np.array([[0.5, length, lift], [gap - 0.5, length, lift]])
    normal = np.vstack([np.tile([np.sin(a), 0.0, np.cos(a)], (len(y), 1)),
                        np.tile([0.0, 0.0, 1.0], (2, 1)),
                        np.tile([-np.sin(a), 0.0, np.cos(a)], (len(y), 1))])
    path = np.r_[np.zeros(len(y)), np.ones(2), np.full(len(y), 2)].astype(np.int32)
    tp = make_toolpath(np.vstack([first, move, second]), normal, path)
    extrude = np.ones(len(path), dtype=bool)
    extrude[len(y):len(y) + 2] = False
    return replace(tp, extrude=extrude)


def _slowed_waypoints(result: plan_module.PlanResult) -> np.ndarray:
    tr, sm = result.trajectory, result.samples
    step = np.linalg.norm(np.diff(tr.tcp, axis=0), axis=1)
    v = step / np.diff(tr.t)
    target = 0.5 * (sm.speed[:-1] + sm.speed[1:])
    ex = sm.extrude[:-1] & (step > 1e-6)
    slowed = np.flatnonzero(ex & (np.abs(v / target - 1.0) > 0.05))
    return np.maximum.accumulate(np.where(tr.waypoint >= 0, tr.waypoint, -1))[slowed]


def test_the_depositing_steps_next_to_a_turning_move_keep_their_speed(
        cell: CellConfig, monkeypatch: pytest.MonkeyPatch) -> None:
    tp = _two_paths()
    last_a, first_b = 39, 43  # the last waypoint of the first line, the first of the second
    new = plan_module.plan(tp, cell)
    assert new.status == "ok"
    slowed = _slowed_waypoints(new)
    # only the job's first and last steps (from and to rest) are slower than the toolpath
    assert set(slowed.tolist()) <= {0, len(tp) - 2}
    # the planning before: the move's directions as sliced, rates central across the stop
    monkeypatch.setattr(plan_module, "ease_moves", lambda samples: samples)
    monkeypatch.setattr(plan_module, "junctions",
                        lambda extrude: np.zeros(len(extrude), dtype=np.int8))
    old = plan_module.plan(tp, cell)
    slowed_old = set(_slowed_waypoints(old).tolist())
    assert last_a - 1 in slowed_old or last_a in slowed_old
    assert first_b in slowed_old
    assert new.report["speed_ratio"]["within_5pct"] > old.report["speed_ratio"]["within_5pct"]
