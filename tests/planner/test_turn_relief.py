"""Turn relief: where the printing direction turns fast, a steadier axis within alpha's band."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import planner.plan as plan_module
from core.stages import Toolpath
from planner.cell import CellConfig
from planner.nozzle_axis import alpha_of
from planner.samples import Samples
from planner.turn_relief import depositing_runs, relieve_turns, turn_acceleration
from tests.planner.synthetic import make_toolpath


def test_turn_acceleration_is_the_curvature_of_the_direction() -> None:
    # a direction turning about z at 1 / r rad/mm: |a''| = 1 / r^2 (finite differences of an
    # analytic curve, uneven spacing)
    r = 2.0
    s = np.cumsum(np.r_[0.0, np.tile([0.2, 0.35], 20)])
    a = np.column_stack([np.cos(s / r), np.sin(s / r), np.zeros_like(s)])
    tcp = np.column_stack([s, np.zeros_like(s), np.zeros_like(s)])
    k = np.arange(len(s))
    prv, nxt = np.maximum(k - 1, 0), np.minimum(k + 1, len(s) - 1)
    acc = turn_acceleration(a, tcp, prv, nxt)
    assert acc[0] == 0.0 and acc[-1] == 0.0  # no neighbour on one side
    assert np.allclose(acc[1:-1], 1.0 / r**2, rtol=0.02)
    assert np.allclose(turn_acceleration(np.tile([0.0, 0.0, 1.0], (len(s), 1)), tcp, prv, nxt),
                       0.0)


def test_depositing_runs_are_numbered_between_moves() -> None:
    ex = np.array([1, 1, 0, 0, 0, 1, 1, 0], dtype=bool)
    run, deposits = depositing_runs(ex)
    # samples 0-2 (2 ends the first run), 5-7 the second; 3 and 4 lie on the move
    assert run.tolist() == [0, 0, 0, -1, -1, 1, 1, 1]
    assert deposits.tolist() == ex[:-1].tolist()


def _wrap(r: float = 2.0, half_deg: float = 34.0, lead: float = 10.0, step: float = 0.4,
          speed: float = 6.0) -> Toolpath:
    """A path around the underside of a lying cylinder (axis y, radius ``r``): a straight
    lead-in at -half_deg, the arc to +half_deg, a straight lead-out; the printing direction
    points to the cylinder's axis (it turns at 1 / r rad/mm on the arc, as on a thin tube's
    first layers), alpha 90 deg everywhere."""
    th0, th1 = np.radians([-half_deg, half_deg])
    t0 = np.array([np.cos(th0), 0.0, np.sin(th0)])
    t1 = np.array([np.cos(th1), 0.0, np.sin(th1)])
    p0 = r * np.array([np.sin(th0), 0.0, -np.cos(th0)])
    p1 = r * np.array([np.sin(th1), 0.0, -np.cos(th1)])
    a = np.arange(lead, 0.0, -step)
    th = np.arange(th0, th1, step / r)
    b = np.arange(0.0, lead + 1e-9, step)
    arc = np.column_stack([r * np.sin(th), np.zeros_like(th), -r * np.cos(th)])
    position = np.vstack([p0 - a[:, None] * t0, arc, p1 + b[:, None] * t1])
    normal = np.vstack([np.tile([-np.sin(th0), 0.0, np.cos(th0)], (len(a), 1)),
                        np.column_stack([-np.sin(th), np.zeros_like(th), np.cos(th)]),
                        np.tile([-np.sin(th1), 0.0, np.cos(th1)], (len(b), 1))])
    return make_toolpath(position, normal, np.zeros(len(position), np.int32), speed=speed)


def _samples(tp: Toolpath) -> Samples:
    """The toolpath as samples in its own frame (the relief needs no pose)."""
    M = len(tp)
    seg = np.diff(tp.position, axis=0)
    t = seg / np.linalg.norm(seg, axis=1, keepdims=True)
    tangent = np.vstack([t, t[-1:]])
    extrude = np.r_[np.ones(M - 1, bool), False]
    arrive = np.vstack([np.zeros((1, 3)), t])
    return Samples(np.array(tp.position), np.array(tp.normal), tangent,
                   np.arange(M, dtype=np.int32), extrude, np.array(tp.speed),
                   np.array(tp.height), arrive)


def test_a_fast_turn_is_relieved_within_the_band_and_a_slow_one_is_left(cell: CellConfig
                                                                      ) -> None:
    s = _samples(_wrap())
    out, turn = relieve_turns(s, cell)
    k = np.arange(len(s.tcp))
    prv, nxt = np.maximum(k - 1, 0), np.minimum(k + 1, len(k) - 1)
    before = turn_acceleration(s.normal, s.tcp, prv, nxt).max()
    after = turn_acceleration(out.normal, s.tcp, prv, nxt).max()
    assert turn.max() > np.radians(1.0) and after < before
    assert turn.max() <= np.radians(cell.planning.smooth_max_deg) + 1e-9
    lo, hi = cell.planning.alpha_min_deg, cell.planning.alpha_max_deg
    leave = np.flatnonzero(s.extrude)
    arrive = np.flatnonzero(np.linalg.norm(s.arrive, axis=1) > 0.5)
    for rows, step in ((leave, s.tangent), (arrive, s.arrive)):  # both steps of a sample
        alpha = np.degrees(alpha_of(-out.normal[rows], step[rows]))
        assert np.all((alpha >= lo) & (alpha <= hi))
    # a wide curve (r = 60 mm: under 1 deg/mm) is not touched
    wide = _samples(_wrap(r=60.0, step=2.0))
    same, none = relieve_turns(wide, cell)
    assert same is wide and not none.any()
    # nor anything where the cell follows the directions as they are
    exact = replace(cell, planning=replace(cell.planning, smooth_length_mm=0.0))
    kept, zero = relieve_turns(s, exact)
    assert kept is s and not zero.any()


def test_a_tight_wrap_keeps_more_speed_with_the_relief(cell: CellConfig,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    tp = _wrap()
    new = plan_module.plan(tp, cell)
    assert new.status == "ok"
    lo, hi = new.report["verified"]["alpha_deg"]
    assert cell.planning.alpha_min_deg <= lo <= hi <= cell.planning.alpha_max_deg
    monkeypatch.setattr(plan_module, "relieve_turns",
                        lambda samples, c: (samples, np.zeros(len(samples.tcp))))
    old = plan_module.plan(tp, cell)
    kept_new = new.report["speed_ratio"]["within_5pct"]
    kept_old = old.report["speed_ratio"]["within_5pct"]
    assert kept_new >= kept_old + 0.05
    assert new.report["turn_relief_deg"]["max"] > 1.0
