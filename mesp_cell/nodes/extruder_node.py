"""The extruder node: owns the extruder driver (Modbus TCP or serial) and publishes its state.

Commands (``extruder/cmd``): ``start`` (args ``rate`` mm^3/s), ``set_rate``, ``stop``,
``reset`` (all latched faults), ``clear`` (latched faults except an e-stop), ``estop``.
A poll loop at ``state_hz`` reads the controller and publishes ``ExtruderState``, and feeds
the controller watchdog at ``heartbeat_hz``; while the screw is off, without a fault, and the
robot at rest, it polls at the idle rate (``idle_pace``) and a command, an e-stop or a robot
state that moves wakes it. Interlocks: the motor stops when the robot or the
supervisor process disappears or an e-stop arrives; a link failure (after the driver's retries)
is published as ``FAULT_LINK`` and the motor is commanded off as soon as the link returns.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Sequence
from typing import Any

from mesp_cell.command_checks import rate_refusal
from mesp_cell.drivers.extruder_base import ExtruderDriver, ExtruderLinkError
from mesp_cell.messages import (
    FAULT_ESTOP,
    FAULT_LINK,
    Command,
    EStop,
    ExtruderState,
    Reply,
    RobotState,
    fault_text,
)
from mesp_cell.nodes.idle_pace import Pace
from mesp_cell.nodes.lifecycle import LifecycleNode, NodeStartError, node_main
from mesp_cell.states import RobotMode

log = logging.getLogger("mesp.extruder")


def make_extruder(params: dict[str, Any]) -> ExtruderDriver:
    """The driver named by ``params['driver']``: "modbus" (default) or "serial"."""
    kind = params.get("driver", "modbus")
    if kind == "modbus":
        from mesp_cell.drivers.extruder_modbus import ModbusExtruder

        return ModbusExtruder(str(params.get("host", "127.0.0.1")), int(params["port"]),
                              timeout=float(params.get("timeout_s", 0.2)),
                              retries=int(params.get("retries", 3)),
                              retry_delay=float(params.get("retry_delay_s", 0.05)),
                              watchdog_ms=int(params.get("watchdog_ms", 500)))
    if kind == "serial":
        from mesp_cell.drivers.extruder_serial import SerialExtruder

        return SerialExtruder(str(params["url"]), timeout=float(params.get("timeout_s", 0.2)),
                              retries=int(params.get("retries", 3)))
    raise ValueError(f"unknown extruder driver '{kind}' (modbus, serial)")


class ExtruderNode(LifecycleNode):
    """See the module docstring. Parameters: driver, host, port (or url), retries, timeout_s,
    retry_delay_s, watchdog_ms, state_hz (100), heartbeat_hz (20), robot and supervisor (node
    names), deadline_s (0.08: an unanswered exchange is a link fault after this), robot_fresh_s
    (0.2: the motor stops when no robot state came for this long while it runs)."""

    def on_configure(self) -> None:
        p = self.params
        try:
            self.driver = make_extruder(p)
        except (KeyError, TypeError, ValueError) as exc:
            raise NodeStartError(f"bad extruder parameters: {exc}",
                                 "correct the extruder's [process.params] in the launch file "
                                 "(driver modbus with host and port, or serial with url)") from exc
        self.robot_name = p.get("robot", "robot")
        self.supervisor_name = p.get("supervisor", "supervisor")
        self.pace = Pace(float(p.get("state_hz", 100.0)))
        # s between controller watchdog heartbeats (20 Hz: well inside the 500 ms watchdog),
        # by time, not by poll count: at rest the polls come at the idle rate
        self.hb_period = 1.0 / float(p.get("heartbeat_hz", 20.0))
        self._hb_t = -math.inf  # monotonic s of the last heartbeat sent
        self.lock = threading.Lock()
        self.connected = False
        self.detail = ""
        self.want_stop = False
        self.deadline_s = float(p.get("deadline_s", 0.08))
        self.robot_fresh_s = float(p.get("robot_fresh_s", 0.2))
        self._robot_t = time.monotonic()  # when the last robot state arrived
        self._robot_moving = False  # the last robot state was a move or a stream
        self._running = False  # the motor ran in the last state read
        self._run_t = 0.0  # monotonic s a state read first showed the motor running
        self._fault = False  # the last state read showed a fault (or no link)
        self._exchange_t = 0.0  # monotonic s the current poll exchange began (0 = none)
        self._exchange_begun = threading.Event()  # wakes ``_watch`` at rest
        self._late_sent = False  # the current exchange was already published as late
        self._exchange_failed0 = 0  # the driver's failed attempts before the current exchange
        self._seq = 0
        try:
            with self.lock:
                self.driver.connect()
                self.driver.stop()
            self.connected = True
        except ExtruderLinkError as exc:
            self.detail = str(exc)
            log.error("%s", exc)

    def on_activate(self) -> None:
        assert self.bus is not None
        self.bus.subscribe("estop", "estop", EStop, self._on_estop)
        self.bus.subscribe(self.robot_name, "state", RobotState, self._on_robot)
        self.bus.watch_presence(self._on_presence)
        self.bus.serve(self._on_command)
        self.spawn(self._poll, "poll")
        self.spawn(self._watch, "watch")

    def on_deactivate(self) -> None:
        self._safe_stop("extruder node shutting down")

    def on_shutdown(self) -> None:
        self.driver.close()

    # -- safety ----------------------------------------------------------------------------
    def _safe_stop(self, why: str, estop: bool = False) -> None:
        log.warning("stopping the extruder: %s", why)
        try:
            with self.lock:
                self.driver.estop() if estop else self.driver.stop()
            self.want_stop = False
        except ExtruderLinkError as exc:
            self.want_stop = True  # commanded off as soon as the link returns
            self.detail = str(exc)
        self.pace.wake()  # the next state shows the stop at once

    def _on_presence(self, node: str, alive: bool) -> None:
        if not alive and node in (self.robot_name, self.supervisor_name):
            self._safe_stop(f"{node} process lost")

    def _on_robot(self, msg: RobotState) -> None:
        self._robot_t = time.monotonic()
        moving = msg.mode in (RobotMode.MOVING, RobotMode.STREAMING)
        was_moving, self._robot_moving = self._robot_moving, moving  # set before the wake
        if moving and not was_moving:
            self.pace.wake()  # full rate before the arm relies on the extruder's state

    def _robot_stale(self, now: float) -> float:
        """s the robot's state is overdue while the screw runs (<= 0: it is fresh): no robot
        state for ``robot_fresh_s`` since the later of its last state and the screw's start (a
        resting robot's loop runs at its idle rate until it hears of the start, then at once
        at its full rate)."""
        return now - max(self._robot_t, self._run_t) - self.robot_fresh_s

    def _watch(self) -> None:
        """Every 10 ms while the motor runs or an exchange is under way (at rest it waits for
        the next exchange): publish a link fault for an exchange past its deadline (the poll
        thread is stuck in it: a frozen controller) or with a failed attempt (a dropped or
        refused connection, at once, while the driver retries), and stop a running motor
        whose robot went silent."""
        while not self.stopping.is_set():
            if self._running or self._exchange_t:
                self.stopping.wait(0.01)
            else:
                self._exchange_begun.wait(self.pace.idle_period)
                self._exchange_begun.clear()
            now = time.monotonic()
            t0 = self._exchange_t
            failed = getattr(self.driver, "attempts_failed", 0) > self._exchange_failed0
            if (t0 and (failed or now - t0 > self.deadline_s) and not self._late_sent
                    and self.bus):
                self._late_sent = True
                detail = ("the link to the extruder controller failed (the driver retries)"
                          if failed else f"the extruder controller did not answer within "
                          f"{self.deadline_s * 1000:.0f} ms")
                log.error("%s", detail)
                self.bus.publish("state", ExtruderState(time.time(), self._seq, 0.0, 0.0, 0.0,
                                                        False, False, FAULT_LINK, detail))
            if self._running and self._robot_stale(now) > 0:
                self._running = False
                self._safe_stop(f"no state from {self.robot_name} for "
                                f"{(now - self._robot_t) * 1000:.0f} ms")

    def _on_estop(self, msg: EStop) -> None:
        self._safe_stop(f"e-stop from {msg.source}", estop=True)

    # -- commands --------------------------------------------------------------------------
    def argument_refusal(self, cmd: Command) -> str:
        return rate_refusal(cmd)

    def _on_command(self, cmd: Command) -> Reply:
        try:
            return self._execute(cmd)
        finally:
            self.pace.wake()  # the next state shows the command's effect at once

    def _execute(self, cmd: Command) -> Reply:
        verb = cmd.verb
        try:
            with self.lock:
                if verb == "start":
                    if cmd.arg("rate") is None:
                        return Reply.refuse("start needs a rate (the job's set-point, mm^3/s)")
                    rate = float(cmd.arg("rate"))
                    if not 0 < rate <= 1000:
                        return Reply.refuse(f"rate {rate} mm^3/s outside (0, 1000]")
                    self.driver.start(rate)
                elif verb == "set_rate":
                    self.driver.set_rate(float(cmd.arg("rate")))
                elif verb == "stop":
                    self.driver.stop()
                elif verb == "reset":
                    self.driver.reset()
                    self.detail = ""
                elif verb == "clear":
                    # Clear a latched watchdog/stall fault before a (re)start; an e-stop is
                    # cleared only by the operator's reset.
                    fault = self.driver.read().fault
                    if fault & FAULT_ESTOP:
                        return Reply.refuse("e-stop latched on the extruder; reset it with "
                                            "`mesp estop --reset`")
                    if fault:
                        self.driver.reset()
                elif verb == "estop":
                    self.driver.estop()
                else:
                    return Reply.refuse(f"unknown extruder command '{verb}'")
        except ExtruderLinkError as exc:
            return Reply.refuse(str(exc))
        return Reply.done()

    # -- poll loop -------------------------------------------------------------------------
    def _poll(self) -> None:
        """Read and publish the state every period; feed the controller watchdog at
        ``heartbeat_hz``. One Modbus exchange per state (a heartbeat write only every few):
        each exchange needs the controller process scheduled, and on a loaded host those
        wake-ups are what delays the state. At rest (the screw off, no fault, the robot not
        moving) it polls at the idle rate (``idle_pace``). A state later than 5 periods is
        logged with where the time went (lock, exchange and retries, publishing, scheduling)."""
        next_t = time.monotonic()
        last_pub = next_t
        slow = 5 * self.pace.period
        while not self.stopping.is_set() and self.bus is not None:
            self.pace.begin()
            self._seq += 1
            t0 = time.monotonic()
            failed0 = getattr(self.driver, "attempts_failed", 0)
            t_lock = t_ex = t0
            try:
                self._late_sent = False
                self._exchange_failed0 = failed0
                self._exchange_t = t0
                self._exchange_begun.set()
                with self.lock:
                    t_lock = time.monotonic()
                    if self.want_stop:
                        self.driver.stop()
                        self.want_stop = False
                    if t_lock - self._hb_t >= self.hb_period:
                        self.driver.heartbeat()
                        self._hb_t = t_lock
                    r = self.driver.read()
                    t_ex = time.monotonic()
                self._exchange_t = 0.0
                if r.running and not self._running:
                    self._run_t = time.monotonic()  # before ``_running``: ``_watch`` reads both
                self._running = r.running
                self._fault = bool(r.fault)
                self.connected = True
                msg = ExtruderState(time.time(), self._seq, r.rate_set, r.rate, r.volume,
                                    r.running, True, r.fault,
                                    fault_text(r.fault))
            except ExtruderLinkError as exc:
                self._exchange_t = 0.0
                if self.connected:
                    log.error("%s", exc)
                self.connected, self.detail, self.want_stop = False, str(exc), True
                self._fault = True
                msg = ExtruderState(time.time(), self._seq, 0.0, 0.0, 0.0, False, False,
                                    FAULT_LINK, self.detail)
            self.bus.publish("state", msg)
            t1 = time.monotonic()
            if t1 - last_pub > slow:
                log.warning("state published %.0f ms after the previous one: scheduling %.0f ms,"
                            " lock %.0f ms, exchange %.0f ms (%d retries), publish %.0f ms",
                            1000 * (t1 - last_pub), 1000 * max(0.0, t0 - max(last_pub, next_t)),
                            1000 * (t_lock - t0), 1000 * (t_ex - t_lock),
                            getattr(self.driver, "attempts_failed", 0) - failed0,
                            1000 * (t1 - t_ex))
            last_pub = t1
            busy = self._running or self._fault or self._robot_moving or self.want_stop
            slow = 5 * self.pace.period_for(busy)
            next_t = self.pace.wait(next_t, busy, t1)


def main(argv: Sequence[str] | None = None) -> int:
    """Process entry point."""
    return node_main(ExtruderNode, argv, "extruder")


if __name__ == "__main__":
    raise SystemExit(main())
