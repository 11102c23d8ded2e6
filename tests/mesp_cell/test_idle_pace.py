"""Idle pacing: the full rate while busy, the idle rate at rest, a wake ends an idle wait at
once; the extruder node's robot staleness allows the idle period only where it applies."""

from __future__ import annotations

import threading
import time

import pytest

from mesp_cell.messages import RobotState
from mesp_cell.nodes.extruder_node import ExtruderNode
from mesp_cell.nodes.idle_pace import IDLE_HZ, Pace, stale_limit
from mesp_cell.states import RobotMode


def test_busy_keeps_the_period_and_never_bursts() -> None:
    pace = Pace(100.0)
    now = time.monotonic()
    due = pace.wait(now, True, now)
    assert due == pytest.approx(now + 0.01)
    late = time.monotonic() + 1.0  # a loop that ran a second late starts a period from now
    assert pace.wait(now, True, late) == pytest.approx(late + 0.01)


def test_rest_waits_the_idle_period_unless_woken() -> None:
    pace = Pace(100.0, idle_hz=5.0)
    assert pace.idle_period == pytest.approx(0.2)
    assert pace.period_for(True) == pytest.approx(0.01)
    t0 = time.monotonic()
    pace.begin()
    pace.wait(t0, False, t0)
    assert time.monotonic() - t0 >= 0.19
    pace.begin()
    threading.Timer(0.02, pace.wake).start()
    t0 = time.monotonic()
    pace.wait(t0, False, t0)
    assert time.monotonic() - t0 < 0.15  # woken at 20 ms, not at 200 ms


def test_a_wake_before_the_wait_is_not_lost() -> None:
    pace = Pace(100.0, idle_hz=1.0)
    pace.begin()
    pace.wake()  # e.g. a command while the loop publishes
    t0 = time.monotonic()
    pace.wait(t0, False, t0)
    assert time.monotonic() - t0 < 0.5


def test_idle_rate_never_exceeds_the_full_rate() -> None:
    assert Pace(4.0).idle_period == pytest.approx(0.25)
    with pytest.raises(ValueError):
        Pace(0.0)


def test_stale_limit_adds_the_idle_period_only_for_an_idle_paced_state() -> None:
    assert stale_limit(0.1, False) == pytest.approx(0.1)
    assert stale_limit(0.1, True) == pytest.approx(0.1 + 1.0 / IDLE_HZ)


def _extruder_node(robot_fresh_s: float) -> ExtruderNode:
    """The node's staleness state alone (no bus, no driver)."""
    node = ExtruderNode.__new__(ExtruderNode)
    node.pace = Pace(100.0)
    node.robot_fresh_s = robot_fresh_s
    node._robot_t, node._robot_moving, node._run_t = 0.0, False, 0.0
    return node


def _robot_state(mode: RobotMode) -> RobotState:
    z = (0.0,) * 6
    return RobotState(time.time(), 1, z, z, (0.0, 0.0, 0.0), mode, "", -1, 0, -1, True,
                      False, "", 0.0)


def test_extruder_judges_a_resting_robot_by_its_idle_rate_until_it_heard_of_the_start() -> None:
    node = _extruder_node(0.1)
    node._on_robot(_robot_state(RobotMode.IDLE))
    t_state = node._robot_t
    node._run_t = t_state + 0.05  # the screw started 50 ms after the robot's idle state
    # its next state is due up to an idle period later: not stale at 0.15 s, stale after 0.2 s
    assert node._robot_stale(t_state + 0.15) < 0
    assert node._robot_stale(t_state + 0.1 + 1.0 / IDLE_HZ + 0.01) > 0
    # a state that came after the start is judged by the full limit
    node._on_robot(_robot_state(RobotMode.IDLE))
    node._run_t = node._robot_t - 0.01
    assert node._robot_stale(node._robot_t + 0.11) > 0


def test_extruder_judges_a_moving_robot_by_the_full_limit_and_wakes_for_it() -> None:
    node = _extruder_node(0.1)
    node.pace.begin()
    node._on_robot(_robot_state(RobotMode.STREAMING))
    assert node.pace._wake.is_set()  # the poll loop goes to the full rate at once
    node._run_t = node._robot_t + 0.05
    assert node._robot_stale(node._robot_t + 0.11) > 0
