"""Speeds of the planned trajectory per toolpath segment, and the print at them."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from core.errors import InputError
from core.stages import Toolpath
from planner.trajectory import Trajectory
from sim.as_planned import segment_speeds, slowdown
from sim.deposition import DepositionConfig, EllipseMorphology, deposit, extrusion_segments

SPEED = 8.0  # mm/s


def _line_toolpath(n: int = 21, step: float = 0.5) -> Toolpath:
    """One straight extruding path along x, n waypoints ``step`` mm apart."""
    x = np.arange(n) * step
    return Toolpath(position=np.column_stack([x, np.zeros(n), np.zeros(n)]),
                    normal=np.tile([0.0, 0.0, 1.0], (n, 1)), layer=np.zeros(n, np.int32),
                    path=np.zeros(n, np.int32), height=np.full(n, 0.6),
                    width=np.full(n, 1.2), speed=np.full(n, SPEED), extrude=np.ones(n, bool),
                    pattern=np.zeros(n, np.int8))


def _trajectory(tp: Toolpath, slow: dict[int, float], between: int = 2) -> Trajectory:
    """Samples at every waypoint and ``between`` more inside each segment; segment k takes
    slow.get(k, 1) times the time the toolpath's speed asks for."""
    seg = np.linalg.norm(np.diff(tp.position, axis=0), axis=1) / SPEED
    dt = seg * np.array([slow.get(k, 1.0) for k in range(len(seg))])
    t_wp = np.concatenate([[0.0], np.cumsum(dt)])
    t = np.concatenate([np.linspace(a, b, between + 1, endpoint=False)
                        for a, b in itertools.pairwise(t_wp)] + [t_wp[-1:]])
    wp = np.full(len(t), -1, np.int32)
    wp[:: between + 1] = np.arange(len(tp))
    m = len(t)
    return Trajectory(t=t, q=np.zeros((m, 6)), qd=np.zeros((m, 6)), tcp=np.zeros((m, 3)),
                      waypoint=wp, alpha=np.full(m, 90.0), extrude=np.ones(m, bool),
                      base_T=np.eye(4), tool_T=np.eye(4), model_T=np.eye(4))


def test_segment_speeds_find_the_slowed_segments() -> None:
    tp = _line_toolpath()
    planned = segment_speeds(tp, _trajectory(tp, {5: 2.0, 6: 4.0}))
    expect = np.ones(len(tp) - 1)
    expect[5], expect[6] = 0.5, 0.25
    assert planned.ratio == pytest.approx(expect)
    assert planned.speed == pytest.approx(SPEED * expect)
    assert planned.duration.sum() == pytest.approx(10.0 / SPEED * (1 + (1 + 3) / 20))


def test_a_slowed_segment_deposits_the_ink_of_its_time() -> None:
    # the extruder pushes C mm^3/s whatever the arm does: C * dt per segment, in a filament
    # whose area C / v grows as the segment slows
    tp = _line_toolpath()
    morph = EllipseMorphology()
    planned = segment_speeds(tp, _trajectory(tp, {10: 3.0}))
    base = extrusion_segments(tp, morph)
    slow = extrusion_segments(tp, morph, segment_speed=planned.speed)
    c = morph.rate_mm3_s
    assert base.volume.sum() == pytest.approx(c * 10.0 / SPEED)
    assert slow.volume.sum() == pytest.approx(c * planned.duration.sum())
    assert slow.volume[10] == pytest.approx(3.0 * base.volume[10])
    assert slow.width[10] * slow.height[10] == pytest.approx(3.0 * base.width[10] * base.height[10])
    summary = slowdown(tp, planned, morph).summary()
    assert summary["extra_ink_mm3"] == pytest.approx(2.0 * base.volume[10])
    assert summary["slowed_length_fraction"] == pytest.approx(1 / 20)
    assert summary["speed_ratio_min"] == pytest.approx(1 / 3)
    cfg = DepositionConfig(voxel_mm=0.2)
    printed = deposit(tp, morph, cfg, segment_speed=planned.speed)
    assert printed.commanded_mm3 == pytest.approx(c * planned.duration.sum())
    assert abs(printed.volume_error) < 1e-3


def test_speed_changing_along_a_segment_is_not_a_slowdown() -> None:
    # 5 -> 15 mm/s over a 12 mm segment, moved exactly as the planner targets it (speed
    # linear in arc length): 12 ln 3 / 10 = 1.32 s, longer than L over the mean speed
    # (1.2 s), yet nothing is slowed and no extra ink is laid
    tp = _line_toolpath(n=3, step=12.0)
    tp = Toolpath(**{**{k: getattr(tp, k) for k in ("position", "normal", "layer", "path",
                                                      "height", "width", "extrude", "pattern")},
                     "speed": np.array([5.0, 15.0, 15.0])})
    t = np.array([0.0, 12.0 * np.log(3.0) / 10.0, 12.0 * np.log(3.0) / 10.0 + 0.8])
    m = len(t)
    trajectory = Trajectory(t=t, q=np.zeros((m, 6)), qd=np.zeros((m, 6)), tcp=np.zeros((m, 3)),
                            waypoint=np.arange(m, dtype=np.int32), alpha=np.full(m, 90.0),
                            extrude=np.ones(m, bool), base_T=np.eye(4), tool_T=np.eye(4),
                            model_T=np.eye(4))
    planned = segment_speeds(tp, trajectory)
    assert planned.target_duration == pytest.approx([12.0 * np.log(3.0) / 10.0, 0.8])
    assert planned.ratio == pytest.approx([1.0, 1.0])
    summary = slowdown(tp, planned, EllipseMorphology()).summary()
    assert summary["slowed_length_fraction"] == 0.0
    assert summary["extra_ink_mm3"] == pytest.approx(0.0, abs=1e-9)


def test_a_trajectory_of_another_toolpath_is_refused() -> None:
    tp = _line_toolpath()
    other = _trajectory(_line_toolpath(n=15), {})
    with pytest.raises(InputError, match="planned for another toolpath"):
        segment_speeds(tp, other)
    with pytest.raises(InputError, match="segments"):
        extrusion_segments(tp, EllipseMorphology(), segment_speed=np.ones(3))


def _long_slowdown() -> tuple[Toolpath, Trajectory]:
    """A 60 mm line at 8 mm/s whose middle 20 mm the arm takes at a quarter of the speed
    (7.5 s instead of 2.5 s): a slowdown much longer than the screw's time constant."""
    tp = _line_toolpath(n=121)
    return tp, _trajectory(tp, {k: 4.0 for k in range(40, 80)})


def test_synced_flow_keeps_the_ink_per_millimetre_through_a_slowdown() -> None:
    from sim.as_planned import effective_speed, synced_segment_ink

    tp, tr = _long_slowdown()
    morph = EllipseMorphology()
    c = morph.rate_mm3_s
    planned = segment_speeds(tp, tr)
    target = c * planned.target_duration  # what the toolpath asks for, per segment
    constant = c * planned.duration
    # an ideal screw (no lag) commanded without lead lays exactly the toolpath's ink
    ideal = synced_segment_ink(tp, tr, planned, c, lead_s=0.0, tau_s=0.0)
    assert ideal.sum() == pytest.approx(target.sum(), rel=2e-3)
    assert np.abs(ideal - target).max() < 0.02 * target.max()
    # the bundled cell's lead 0.3 s and tau 0.2 s: short of ideal only near the two changes,
    # and a small part of what a constant rate adds
    real = synced_segment_ink(tp, tr, planned, c, lead_s=0.3, tau_s=0.2)
    extra_constant = constant.sum() - target.sum()
    assert abs(real.sum() - target.sum()) < 0.05 * extra_constant
    assert np.abs(real[45:75] - target[45:75]).max() < 0.01 * target[45:75].max()
    # printed at the effective speed C L / ink: the deposit holds that ink
    speed = effective_speed(tp, planned, real, c)
    segs = extrusion_segments(tp, morph, segment_speed=speed)
    assert segs.volume.sum() == pytest.approx(real.sum(), rel=1e-9)
    summary = slowdown(tp, planned, morph, real).summary()
    assert abs(summary["extra_ink_mm3"]) < 0.05 * extra_constant
    assert slowdown(tp, planned, morph).summary()["extra_ink_mm3"] == pytest.approx(
        extra_constant)
