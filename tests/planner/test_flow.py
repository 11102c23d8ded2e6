"""Extrusion synchronised with the planned motion (planner.flow)."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import InputError
from core.stages import Toolpath
from planner.flow import MIN_FLOW_SCALE, asked_acceleration, knot_flow_scale, segment_speeds
from planner.trajectory import Trajectory
from tests.planner.synthetic import make_toolpath


def _two_paths() -> tuple[Toolpath, Trajectory]:
    """Two straight paths of 5 waypoints 1 mm apart at 10 mm/s; one sample between
    waypoints; segment 1 (path 0) is moved at half speed, segment 6 (path 1) at 1/100; the
    move between the paths (segment 4) does not deposit."""
    x = np.arange(5.0)
    pos = np.concatenate([np.column_stack([x, np.zeros(5), np.zeros(5)]),
                          np.column_stack([x[::-1], np.full(5, 2.0), np.zeros(5)])])
    tp = make_toolpath(pos, np.tile([0.0, 0.0, 1.0], (10, 1)), np.repeat([0, 1], 5))
    slow = {1: 2.0, 6: 100.0}
    seg = np.linalg.norm(np.diff(pos, axis=0), axis=1) / 10.0
    dt = seg * np.array([slow.get(k, 1.0) for k in range(9)])
    t_wp = np.concatenate([[0.0], np.cumsum(dt)])
    t = np.sort(np.concatenate([t_wp, 0.5 * (t_wp[:-1] + t_wp[1:])]))
    wp = np.full(len(t), -1, np.int32)
    wp[::2] = np.arange(10)
    extrude = np.ones(len(t), bool)
    extrude[8:10] = False  # from waypoint 4 to waypoint 5: the move between the paths
    m = len(t)
    tr = Trajectory(t=t, q=np.zeros((m, 6)), qd=np.zeros((m, 6)), tcp=np.zeros((m, 3)),
                    waypoint=wp, alpha=np.full(m, 90.0), extrude=extrude, base_T=np.eye(4),
                    tool_T=np.eye(4), model_T=np.eye(4))
    return tp, tr


def test_knot_scale_is_the_speed_ratio_of_the_step_it_starts() -> None:
    tp, tr = _two_paths()
    scale = knot_flow_scale(tp, tr)
    expect = np.ones(len(tr.t))
    expect[[2, 3]] = 0.5  # the two steps of segment 1
    expect[[12, 13]] = MIN_FLOW_SCALE  # 1/100 of the speed: clipped, the screw keeps a trickle
    assert scale == pytest.approx(expect)
    ratio = segment_speeds(tp, tr).ratio
    assert ratio[1] == pytest.approx(0.5) and ratio[6] == pytest.approx(0.01)


def test_a_trajectory_of_another_toolpath_is_refused() -> None:
    tp, tr = _two_paths()
    short = make_toolpath(tp.position[:6], tp.normal[:6], tp.path[:6])
    with pytest.raises(InputError, match="another toolpath"):
        knot_flow_scale(short, tr)


def test_asked_acceleration_peaks_at_the_faster_end_of_a_speed_change() -> None:
    # speed linear in arc length from v0 to v1 over L: v dv/dx = v (v1 - v0) / L, largest
    # at the faster end; nothing on a move between paths or a segment of no length
    tp, _ = _two_paths()
    speed = np.full(10, 10.0)
    speed[2], speed[7] = 20.0, 4.0  # segments 1, 2 (path 0) and 6, 7 (path 1): 1 mm each
    extrude = np.ones(10, bool)
    tp = Toolpath(position=tp.position, normal=tp.normal, layer=tp.layer, path=tp.path,
                  height=tp.height, width=tp.width, speed=speed, extrude=extrude,
                  pattern=tp.pattern)
    acc = asked_acceleration(tp)
    expect = np.zeros(9)
    expect[[1, 2]] = 20.0 * 10.0 / 1.0
    expect[[6, 7]] = 10.0 * 6.0 / 1.0
    assert acc == pytest.approx(expect)
    assert acc[4] == 0.0  # the move between the paths (2 mm, other path id)
