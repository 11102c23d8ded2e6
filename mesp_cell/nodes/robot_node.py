"""The robot node: owns the arm driver (UR5e over RTDE, or a twin) and streams trajectories.

Commands (``robot/cmd``): ``load`` (path, sha256 of trajectory.npz) checks and resamples a
trajectory; ``move`` (args ``to``: "home" | "sample", ``sample``) moves there on a checked safe
path (``robot_moves``);
``stream`` (args ``start``, ``end``, ``after_waypoint``, ``lead_s``, ``rate``: the job's
extruder set-point, from its profile) streams the
samples ``start`` .. ``end`` - 1 (default: to the end; ``robot_streams``) and
switches the extruder ``lead_s`` ahead of every change of deposition, on the servo clock (lead
compensation of the extruder's flow response); while depositing it also scales the rate with
the arm's planned speed, ``lead_s`` ahead (``set_rate`` to the set-point x
``StreamPlan.flow_at``, when it moves by more than FLOW_STEP of it, at most every
FLOW_INTERVAL_S of wall time), so the ink per millimetre stays the slicer's where the planner
slowed the arm (``sync_flow``, default on);
``stop``; ``reset`` clears a latched e-stop; ``status`` answers the latched e-stop (reason,
time), the motion mode and the last stream's stop.
Motions run in one motion thread; their end is published as a ``StreamEvent`` on
``robot/event``. The state is published at ``state_hz`` while the arm moves or the screw runs,
at the idle rate otherwise (``idle_pace``; at least twice the controller's watchdog rate).
Interlocks, checked before every servo sample: no e-stop, the extruder and supervisor
processes present, and the extruder running (fresh state) wherever the trajectory deposits,
delivering the commanded flow (``interlock``, ``flow_check``).
Losing the extruder's liveliness token stops the stream at once. Whenever a motion stops early,
the screw is stopped in the same moment: on the controller directly (``ScrewStop``, its own
pre-opened Modbus link, parameter ``screw_stop``) and through the extruder node. Every
deposition waypoint passed is appended to the job's ledger (``print_ledger``) before it is
published: what the robot printed, which the supervisor resumes after. ``load`` with ``fresh``
starts an empty ledger (a new print).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from core.errors import InputError
from mesp_cell.command_checks import load_refusal, stream_refusal
from mesp_cell.drivers.extruder_plant import PlantParams
from mesp_cell.drivers.robot_base import RobotLinkError, ServoConfig
from mesp_cell.drivers.screw_stop import ScrewStop
from mesp_cell.drivers.stream import ServoStream, StreamPlan
from mesp_cell.messages import (
    Command,
    EStop,
    ExtruderState,
    Reply,
    RobotState,
    StreamEvent,
)
from mesp_cell.nodes.extruder_switch import Switcher, wall_clock
from mesp_cell.nodes.flow_check import FlowCheck, FlowResponse
from mesp_cell.nodes.idle_pace import IDLE_HZ, Pace
from mesp_cell.nodes.interlock import Interlock
from mesp_cell.nodes.lifecycle import LifecycleNode, NodeStartError, node_main
from mesp_cell.nodes.print_ledger import Ledger
from mesp_cell.nodes.robot_driver import cell_of, home_and_tool, make_driver
from mesp_cell.nodes.robot_moves import RobotMoves
from mesp_cell.nodes.robot_streams import RobotStreams
from mesp_cell.states import RobotMode

log = logging.getLogger("mesp.robot")


class RobotNode(RobotStreams, RobotMoves, LifecycleNode):
    """See the module docstring. Parameters: backend, host, servo (table), home_deg, tool_T,
    sim_clock (twin backends: the clock file shared with the extruder emulator), state_hz
    (100), extruder (node name), supervisor (node name), extruder_fresh_s (0.05: max age of the
    extruder state), switch_margin_s (0.1: time allowed for a switch-on to show), sync_flow
    (true: scale the extrusion rate with the arm's planned speed), flow_tau_s (the extruder's
    flow time constant, s of its clock; default the emulator's), screw_stop ("host:port" of
    the extruder controller for the direct screw stop; "" = through the extruder node only)."""

    def on_configure(self) -> None:
        p = self.params
        try:
            self.servo = ServoConfig(**p.get("servo", {}))
            self.cell = cell_of(p)
            self.driver = make_driver(p, self.servo, self.cell)
        except (TypeError, ValueError, InputError) as exc:
            raise NodeStartError(f"bad robot parameters: {exc}",
                                 "correct the robot's [process.params] in the launch file "
                                 "(launch/sim.toml shows every key)") from exc
        try:
            self.driver.connect()
        except RobotLinkError as exc:
            host = p.get("host", "")
            raise NodeStartError(str(exc), f"check that the robot at {host} is powered on, in "
                                 "remote control, with RTDE enabled and reachable (ping "
                                 f"{host}); or run the twin: mesp launch sim") from exc
        self.home, _ = home_and_tool(p, self.cell)
        self.reach: Any = None  # planner.orientation.Reach of the loaded job's gel level
        self.extruder_name = p.get("extruder", "extruder")
        self.supervisor_name = p.get("supervisor", "supervisor")
        self.margin_s = float(p.get("switch_margin_s", 0.1))
        self.sync_flow = bool(p.get("sync_flow", True))
        try:
            response = FlowResponse(float(p.get("flow_tau_s", PlantParams.tau_s)),
                                    time_scale=self.servo.time_scale, latency_s=self.margin_s)
        except ValueError as exc:
            raise NodeStartError(f"bad robot parameters: {exc}",
                                 "set flow_tau_s to the extruder's flow time constant") from exc
        self.interlock = Interlock(self.extruder_name, self.supervisor_name,
                                   float(p.get("extruder_fresh_s", 0.05)), FlowCheck(response))
        self.screw: ScrewStop | None = None
        link = str(p.get("screw_stop", "") or "")
        if link:
            host, _, port = link.rpartition(":")
            self.screw = ScrewStop(host, int(port))
        clock = getattr(self.driver, "clock", None)  # a twin's clock, shared with the extruder
        self.switcher = Switcher(self._send_switch, clock.now if clock else wall_clock,
                                 self.servo.time_scale, clock,
                                 getattr(self.driver, "sim_now", None))
        # the state loop kicks the controller's watchdog: at rest too, five times as often as
        # it needs (a loop held up by most of a period still kicks in time)
        self.pace = Pace(float(p.get("state_hz", 100.0)),
                         max(IDLE_HZ, 5.0 * self.servo.watchdog_hz))
        self.plan: StreamPlan | None = None
        self.job_id = ""
        self.job_dir: Path | None = None
        self.stream: ServoStream | None = None
        self.mode = RobotMode.IDLE
        self.stop_reason, self.stop_t = "", 0.0
        self.waypoint = -1
        self._motion_lock = threading.Lock()
        self._motion: threading.Thread | None = None
        self._abort_move = threading.Event()
        self._in_motion = threading.Event()
        self._seq = 0

    @property
    def estopped(self) -> str:
        """The latched e-stop's reason ("" = none)."""
        return self.interlock.estopped

    def on_activate(self) -> None:
        assert self.bus is not None
        self.bus.subscribe(self.extruder_name, "state", ExtruderState, self._on_extruder)
        self.bus.subscribe("estop", "estop", EStop, self._on_estop)
        self.bus.watch_presence(self._on_presence)
        self.bus.serve(self._on_command)
        self.spawn(self._publish_state, "state")
        self.spawn(lambda: self.switcher.run(self.stopping), "switcher")

    def _send_switch(self, verb: str, rate: float) -> str:
        """Ask the extruder node to ``verb`` at ``rate``; '' when done, else why not."""
        if self.bus is None:
            return "no bus"
        reply = self.bus.request(self.extruder_name, Command.make(verb, rate=rate), 1.0)
        return "" if reply.ok else reply.reason

    def on_deactivate(self) -> None:
        self._halt("robot node shutting down")

    def on_shutdown(self) -> None:
        if self._motion is not None:
            self._motion.join(2.0)
        self.driver.close()
        if self.screw is not None:
            self.screw.close()

    # -- inputs ----------------------------------------------------------------------------
    def _on_presence(self, node: str, alive: bool) -> None:
        if alive:
            self.interlock.alive.add(node)
            return
        self.interlock.alive.discard(node)
        if node in (self.extruder_name, self.supervisor_name):
            self._halt(f"{node} process lost")
            # A killed process's token may be withdrawn after its restarted successor's
            # appeared: ask the bus again, so the successor is not taken for gone.
            self.spawn(lambda: self._recheck(node), f"recheck-{node}")

    def _on_extruder(self, msg: ExtruderState) -> None:
        was = self.interlock.ext
        self.interlock.on_extruder(msg)
        if msg.running and not (was is not None and was.running):
            self.pace.wake()  # the screw runs: the extruder node judges this node's state

    def _busy_pace(self) -> bool:
        """The state goes out at the full rate: the arm moves or the screw runs."""
        ext = self.interlock.ext
        return self._in_motion.is_set() or (ext is not None and ext.running)

    def _recheck(self, node: str) -> None:
        time.sleep(0.3)
        if self.bus is not None and node in self.bus.alive_nodes(1.0):
            self.interlock.alive.add(node)

    def _on_estop(self, msg: EStop) -> None:
        self.interlock.latch_estop(f"e-stop from {msg.source}"
                                   + (f": {msg.reason}" if msg.reason else ""))
        self._halt(self.estopped)

    def _halt(self, reason: str) -> None:
        stream = self.stream
        if stream is not None:
            stream.stop(reason)
            self._stop_screw(reason)
        self._abort_move.set()

    def _stop_screw(self, reason: str) -> None:
        """Command the screw to zero now: on the controller directly and through the node."""
        if self.screw is not None:
            self.screw.trigger(reason)
        self.switcher.put("stop", 0.0)

    # -- commands --------------------------------------------------------------------------
    def argument_refusal(self, cmd: Command) -> str:
        if cmd.verb == "load":
            return load_refusal(self, cmd)
        if cmd.verb == "stream":
            return stream_refusal(self, cmd)
        return ""

    def _on_command(self, cmd: Command) -> Reply:
        verb = cmd.verb
        if verb == "stop":
            self._halt(cmd.arg("reason", "stop requested"))
            return Reply.done()
        if verb == "reset":
            self.interlock.estopped = ""
            return Reply.done()
        if verb == "status":
            return Reply.done(estopped=self.estopped, estop_t=self.interlock.estop_t,
                              mode=self.mode,
                              job_id=self.job_id, stop_reason=self.stop_reason,
                              stop_t=self.stop_t, waypoint=self.waypoint)
        if verb == "load":
            if self._busy():
                return Reply.refuse("robot is busy; stop it first")
            plan = StreamPlan.load(Path(cmd.path), self.servo.dt, cmd.sha256)
            self.plan, self.job_id = plan, cmd.job_id
            self.job_dir = Path(cmd.path).parent
            if cmd.arg("fresh", False):  # a new print: nothing of it printed yet
                Ledger(self.job_dir, fresh=True).close()
            self.reach = self._reach(self.job_dir)
            return Reply.done(samples=plan.samples, layers=plan.layers,
                              waypoints=int(plan.wp_id.size), duration_s=plan.samples * plan.dt)
        if verb in ("move", "stream"):
            if self.estopped:
                return Reply.refuse(f"{self.estopped}; reset it with `mesp estop --reset`")
            if not self.driver.connected() or self.driver.protective_stopped():
                return Reply.refuse("robot not ready (link down or protective stop)")
            if self._busy():
                return Reply.refuse("robot is busy with another motion")
            if verb == "move":
                return self._start_move(cmd)
            return self._start_stream(cmd)
        return Reply.refuse(f"unknown robot command '{verb}'")

    def _busy(self) -> bool:
        # A flag, not the thread's liveness: the motion is over once its end event is out,
        # even if its thread has not returned yet.
        return self._in_motion.is_set()

    # -- outputs ---------------------------------------------------------------------------
    def _event(self, ev: StreamEvent) -> None:
        if self.bus is not None:
            self.bus.publish("event", ev, express=True)

    def _publish_state(self) -> None:
        next_t = time.monotonic()
        while not self.stopping.is_set() and self.bus is not None:
            self.pace.begin()
            busy = self._busy_pace()
            d = self.driver
            q, qd = np.degrees(d.joints()), np.degrees(d.joint_speeds())
            stream, plan = self.stream, self.plan
            self._seq += 1
            mode = RobotMode.FAULT if (not d.connected() or d.protective_stopped()) else self.mode
            self.bus.publish("state", RobotState(
                time.time(), self._seq, tuple(q.tolist()), tuple(qd.tolist()),
                tuple(d.tcp_mm().tolist()), mode, self.job_id,
                stream.sample if stream is not None else -1,
                plan.samples if plan is not None else 0, self.waypoint, d.connected(),
                d.protective_stopped(), self.stop_reason, self.stop_t))
            if d.connected():
                d.kick_watchdog()
            elif not self._busy():
                d.reconnect()
            next_t = self.pace.wait(next_t, busy, time.monotonic())


def main(argv: Sequence[str] | None = None) -> int:
    """Process entry point."""
    return node_main(RobotNode, argv, "robot")


if __name__ == "__main__":
    raise SystemExit(main())
