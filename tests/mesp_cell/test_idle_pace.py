"""Idle pacing: the full rate while busy, the idle rate at rest, a wake ends an idle wait at
once; the extruder node judges the robot's silence from the screw's start and keeps feeding the
controller's watchdog at its heartbeat rate at rest."""

from __future__ import annotations

import itertools
import threading
import time

import pytest

from mesp_cell.drivers.extruder_base import ExtruderReading
from mesp_cell.messages import RobotState
from mesp_cell.nodes.extruder_node import ExtruderNode
from mesp_cell.nodes.idle_pace import IDLE_HZ, Pace
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


def test_extruder_judges_a_resting_robot_from_the_screws_start() -> None:
    node = _extruder_node(0.1)
    node._on_robot(_robot_state(RobotMode.IDLE))
    t_state = node._robot_t
    node._run_t = t_state + 0.05  # the screw started 50 ms after the robot's idle state
    # the robot has robot_fresh_s from the start to answer (its loop wakes when it hears of it)
    assert node._robot_stale(t_state + 0.14) < 0
    assert node._robot_stale(t_state + 0.16) > 0
    # a state that came after the start is judged from that state
    node._on_robot(_robot_state(RobotMode.IDLE))
    node._run_t = node._robot_t - 0.01
    assert node._robot_stale(node._robot_t + 0.09) < 0
    assert node._robot_stale(node._robot_t + 0.11) > 0


def test_extruder_wakes_for_a_moving_robot_after_it_knows_it_moves() -> None:
    node = _extruder_node(0.1)
    node.pace.begin()
    seen: list[bool] = []
    node.pace.wake = lambda: seen.append(node._robot_moving)  # type: ignore[method-assign]
    node._on_robot(_robot_state(RobotMode.STREAMING))
    assert seen == [True]  # a poll woken by it reads the arm as moving (no idle wait lost)
    node._on_robot(_robot_state(RobotMode.STREAMING))
    assert seen == [True]  # only the change wakes


class _Driver:
    """A controller at rest that records when the host fed its watchdog."""

    def __init__(self) -> None:
        self.beats: list[float] = []

    def heartbeat(self) -> None:
        self.beats.append(time.monotonic())

    def read(self) -> ExtruderReading:
        return ExtruderReading(0.0, 0.0, 0.0, False, 0, 0)

    def stop(self) -> None:
        pass


class _Bus:
    def publish(self, topic: str, msg: object) -> None:
        pass


def test_extruder_feeds_the_controller_watchdog_at_its_heartbeat_rate_at_rest() -> None:
    """At rest the polls come at the idle rate; the heartbeat (20 Hz, within the controller's
    500 ms watchdog) goes out with every poll that is due one, not every few polls."""
    node = ExtruderNode.__new__(ExtruderNode)
    node.pace = Pace(100.0)
    node.driver = _Driver()  # type: ignore[assignment]
    node.bus = _Bus()  # type: ignore[assignment]
    node.stopping = threading.Event()
    node.lock = threading.Lock()
    node.hb_period, node._hb_t = 1.0 / 20.0, float("-inf")
    node._seq, node.want_stop, node.connected, node.detail = 0, False, False, ""
    node._robot_t, node._robot_moving, node._run_t = 0.0, False, 0.0
    node._running = node._fault = node._late_sent = False
    node._exchange_t, node._exchange_failed0 = 0.0, 0
    node._exchange_begun = threading.Event()
    poll = threading.Thread(target=node._poll, daemon=True)
    poll.start()
    time.sleep(1.0)
    node.stopping.set()
    poll.join(2.0)
    beats = node.driver.beats  # type: ignore[attr-defined]
    assert len(beats) >= 0.8 * IDLE_HZ  # one with every idle poll
    assert max(b - a for a, b in itertools.pairwise(beats)) < 0.3  # watchdog 0.5 s
