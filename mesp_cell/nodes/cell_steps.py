"""The supervisor's steps on the cell's nodes: ask, move, wait for a motion's end.

``CellSteps`` holds what one print asks of the robot and extruder nodes: a request with its
timeout, a checked move and the wait for its end event, an extruder command, the retract of
an aborted job's nozzle. A step that cannot go on raises ``Stopped`` with the reason, which
the print (``print_loop``) turns into the job's paused, aborted or interrupted state.
"""

from __future__ import annotations

import queue
import threading
import time
from typing import Any

from mesp_cell.bus.session import Bus
from mesp_cell.drivers.sim_clock import SimClock
from mesp_cell.jobs import JobStore
from mesp_cell.messages import (
    Command,
    ExtruderState,
    Reply,
    RobotState,
    StreamEvent,
    WaypointReached,
)
from mesp_cell.states import StreamEnd


class Stopped(Exception):
    """The print stopped early; ``args[0]`` is the reason."""


class CellSteps:
    """The steps of one print on the nodes, mixed into ``SupervisorNode`` (which sets these
    attributes in ``on_configure``)."""

    bus: Bus | None
    store: JobStore
    cell: str
    names: dict[str, str]
    timeouts: dict[str, float]
    setpoint: float
    true_per_nominal: float
    lead_s: float
    prime_s: float
    dt: float
    time_scale: float
    sim_clock: SimClock | None
    settle_s: float
    alive: set[str]
    events: queue.Queue[StreamEvent]
    waypoints: queue.Queue[WaypointReached]
    robot_state: RobotState | None
    extruder_state: ExtruderState | None
    current: str
    request: str
    _lock: threading.Lock

    def _retract(self, job_id: str) -> str:
        """Move home on the robot's checked safe path (retract along the nozzle axis, transfer
        above the gel); returns what happened, for the job's history."""
        asked = time.time()
        reply = self._request(self.names["robot"], Command.make("move", job_id, to="home"))
        if not reply.ok:
            return f"nozzle not retracted: {reply.reason}"
        try:
            ev = self._wait_event(job_id, self.timeouts["move"], asked)
        except Stopped as exc:
            return f"nozzle not retracted: {exc}"
        if ev.kind != StreamEnd.MOVED:
            return f"nozzle not retracted: {ev.reason or 'move interrupted'}"
        return "nozzle retracted along its axis out of the gel and parked at home"

    def _request(self, node: str, cmd: Command, timeout: float = 5.0) -> Reply:
        assert self.bus is not None
        return self.bus.request(node, cmd, timeout)

    def _wait_event(self, job_id: str, timeout: float, since: float = 0.0) -> StreamEvent:
        """The next end event of ``job_id``'s motion that ended at or after ``since`` (s since
        the epoch: the request's time; an earlier one is a stale stream end, e.g. the stop
        of a paused stream, which each repeated stop request may announce again)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.names["robot"] not in self.alive:
                raise Stopped(f"{self.names['robot']} process lost")
            try:
                ev = self.events.get(timeout=0.05)
            except queue.Empty:
                continue
            if ev.job_id == job_id and ev.t >= since:
                return ev
        raise Stopped(f"robot did not finish within {timeout:g} s")

    def _check_request(self) -> None:
        """Raise ``Stopped`` if the operator paused or aborted the current job."""
        if self.request:
            raise Stopped(f"{self.request} requested")

    def _move(self, job_id: str, **args: Any) -> None:
        self._check_request()
        asked = time.time()
        reply = self._request(self.names["robot"], Command.make("move", job_id, **args))
        if not reply.ok:
            raise Stopped(reply.reason)
        ev = self._wait_event(job_id, self.timeouts["move"], asked)
        if ev.kind != StreamEnd.MOVED:
            raise Stopped(ev.reason or "move interrupted")

    def _extruder(self, verb: str, **args: Any) -> None:
        reply = self._request(self.names["extruder"], Command.make(verb, **args), 2.0)
        if not reply.ok:
            raise Stopped(f"extruder refused {verb}: {reply.reason}")

