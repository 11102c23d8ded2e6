"""The robot node: owns the arm driver (UR5e over RTDE, or a twin) and streams trajectories.

Commands (``robot/cmd``): ``load`` (path, sha256 of trajectory.npz) checks and resamples a
trajectory; ``move`` (args ``to``: "home" | "sample", ``sample``) moves there on a checked safe
path (``planner.entry``: retract along the nozzle axis out of the gel, transfer above it,
plunge along the target's axis; refused with its reason if the cell model finds no such path);
``stream`` (args ``start``, ``end``, ``after_waypoint``, ``lead_s``, ``rate``: the job's
extruder set-point, from its profile) streams the
samples ``start`` .. ``end`` - 1 (default: to the end) and
switches the extruder ``lead_s`` ahead of every change of deposition, on the servo clock (lead
compensation of the extruder's flow response); while depositing it also scales the rate with
the arm's planned speed, ``lead_s`` ahead (``set_rate`` to the set-point x
``StreamPlan.flow_at``, when it moves by more than FLOW_STEP of it, at most every
FLOW_INTERVAL_S of wall time), so the ink per millimetre stays the slicer's where the planner
slowed the arm (``sync_flow``, default on);
``stop``; ``reset`` clears a latched e-stop; ``status`` answers the latched e-stop (reason,
time), the motion mode and the last stream's stop.
Motions run in one motion thread; their end is published as a ``StreamEvent`` on
``robot/event``. Interlocks, checked before every servo sample: no e-stop,
the extruder and supervisor processes present, and the extruder running (fresh state) wherever
the trajectory deposits. Losing the extruder's liveliness token stops the stream at once.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from core.errors import InputError
from mesp_cell.command_checks import load_refusal, stream_refusal
from mesp_cell.drivers.robot_base import RobotDriver, RobotLinkError, ServoConfig
from mesp_cell.drivers.stream import ServoStream, StreamPlan, StreamResult
from mesp_cell.messages import (
    Command,
    EStop,
    ExtruderState,
    Reply,
    RobotState,
    StreamEvent,
    WaypointReached,
)
from mesp_cell.nodes.lifecycle import LifecycleNode, NodeStartError, node_main
from planner.cell import CellConfig, load_cell

END = "\x00end"  # guard reason that ends a stream at its ``end`` sample (not a stop)

log = logging.getLogger("mesp.robot")


def cell_of(params: dict[str, Any]) -> CellConfig:
    """The cell description of this robot: ``params['cell_file']`` ("" = the bundled cell)."""
    cell = cell_file_of(params)
    return load_cell(Path(cell) if cell else None)


def home_and_tool(params: dict[str, Any], cell: CellConfig) -> tuple[np.ndarray, np.ndarray]:
    """Home (6,) rad and tool (4, 4) mm: the cell's, unless the launch file overrides them
    (``home_deg``, ``tool_T``)."""
    home = np.radians(params.get("home_deg", cell.robot.home_deg))
    tool = params.get("tool_T")
    tool_T = cell.tool.tool_T if tool is None else np.asarray(tool, dtype=np.float64)
    return home, tool_T


def make_driver(params: dict[str, Any], servo: ServoConfig,
                cell: CellConfig | None = None) -> RobotDriver:
    """The driver named by ``params['backend']``: "twin" (default), "mujoco" or "ur5e"."""
    backend = params.get("backend", "twin")
    home, tool_T = home_and_tool(params, cell if cell is not None else cell_of(params))
    if backend in ("twin", "mujoco"):
        from mesp_cell.drivers.sim_clock import SimClock

        # the simulated cell's clock, shared with the emulated extruder ("" = private)
        clock = SimClock(servo.time_scale, params.get("sim_clock") or None)
    if backend == "twin":
        from mesp_cell.drivers.robot_twin import KinematicTwin

        return KinematicTwin(servo, q0=home, tool_T=tool_T, clock=clock)
    if backend == "mujoco":
        from mesp_cell.drivers.robot_twin import mujoco_twin

        return mujoco_twin(servo, q0=home, tool_T=tool_T, cell_file=cell_file_of(params),
                           clock=clock)
    if backend == "ur5e":
        from mesp_cell.drivers.ur5e_rtde import UR5eRTDE

        return UR5eRTDE(str(params["host"]), servo, tool_T=tool_T)
    raise ValueError(f"unknown robot backend '{backend}' (twin, mujoco, ur5e)")


def cell_file_of(params: dict[str, Any]) -> str | None:
    """The cell file of the MuJoCo backend (None = the bundled cell)."""
    cell = params.get("cell_file")
    return str(cell) if cell else None


def must_run_mask(extrude: np.ndarray, lead_n: int, margin_n: int, start: int) -> np.ndarray:
    """Samples at which the extruder must already be running.

    The robot node switches the extruder ``lead_n`` samples ahead of each change of
    ``extrude`` (``cmd_on``); a deposition sample needs the motor on unless its switch-off lead
    has begun or the last switch-on was less than ``margin_n`` samples ago (command latency).
    A stream that starts with the extruder on (the supervisor started it) counts as switched on
    before ``start``. The whole window since the last switch-on counts, so travel moves shorter
    than the margin cannot make a fresh switch-on look settled.

    Args:
        extrude: (K,) bool. Returns (K,) bool.
    """
    K = extrude.shape[0]
    return _must_run(extrude, np.arange(K), K, lead_n, margin_n, start, -1)[0]


def _must_run(extrude: Any, idx: np.ndarray, K: int, lead_n: int, margin_n: int, start: int,
              last_off_before: int) -> tuple[np.ndarray, int]:
    """``must_run_mask`` at the consecutive samples ``idx`` of K, given the last "off" sample
    before them (-1: none); returns the mask and the last "off" sample up to ``idx[-1]``.
    ``extrude`` is indexable with an int array (a (K,) bool array or ``ServoExtrude``)."""
    ext = np.asarray(extrude[idx], dtype=bool)
    cmd_on = np.asarray(extrude[np.minimum(idx + lead_n, K - 1)], dtype=bool)
    off = ~cmd_on & (idx >= start)
    # last "off" sample at or before k
    last_off = np.maximum(np.maximum.accumulate(np.where(off, idx, -1)), last_off_before)
    settled = (last_off < start) | (idx - last_off - 1 >= margin_n)
    return ext & cmd_on & settled, int(last_off[-1]) if len(idx) else last_off_before


class MustRun:
    """``must_run_mask`` of a stream from ``start``, computed a chunk of samples at a time as
    the stream asks for them (a whole long job's mask would hold tens of millions of
    samples). Call it with non-decreasing sample indices >= ``start``."""

    CHUNK = 1 << 16

    def __init__(self, extrude: Any, lead_n: int, margin_n: int, start: int) -> None:
        self.extrude, self.K = extrude, len(extrude)
        self.lead_n, self.margin_n, self.start = lead_n, margin_n, start
        self.c0 = start
        self.mask = np.zeros(0, dtype=bool)
        self.last_off = -1

    def __call__(self, k: int) -> bool:
        if k < self.c0:
            raise ValueError(f"sample {k} before the stream's window at {self.c0}")
        while k >= self.c0 + len(self.mask):
            c0 = self.c0 + len(self.mask)
            idx = np.arange(c0, min(c0 + self.CHUNK, self.K), dtype=np.int64)
            if not len(idx):
                raise IndexError(f"sample {k} beyond the {self.K} samples")
            self.mask, self.last_off = _must_run(self.extrude, idx, self.K, self.lead_n,
                                                 self.margin_n, self.start, self.last_off)
            self.c0 = c0
        return bool(self.mask[k - self.c0])


FLOW_STEP = 0.03  # a rate change smaller than this x the set-point is not sent
FLOW_INTERVAL_S = 0.02  # s of wall time between two rate commands, at least (bus, Modbus)


class FlowSync:
    """The rate commands of one stream that keep the ink per millimetre where the arm is
    slower than the toolpath: at servo sample k, the set-point ``rate`` x
    ``plan.flow_at(k + lead_n)`` (the step
    the nozzle will be on when the screw has followed), sent when it differs from the last
    sent by more than FLOW_STEP x ``rate`` and ``interval_n`` samples have passed since."""

    def __init__(self, plan: StreamPlan, rate: float, lead_n: int, end: int, interval_n: int,
                 start: int) -> None:
        self.plan, self.rate, self.lead_n, self.end = plan, rate, lead_n, end
        self.interval_n = max(int(interval_n), 1)
        self.sent = rate  # the supervisor starts the extruder at the job's set-point
        self.sent_k = start - self.interval_n

    def _target(self, k: int) -> float:
        return self.rate * self.plan.flow_at(min(k + self.lead_n, self.end - 1))

    def switch_on(self, k: int) -> float:
        """The rate to start the extruder at, at sample ``k``."""
        self.sent, self.sent_k = self._target(k), k
        return self.sent

    def __call__(self, k: int) -> float | None:
        """The rate to command at sample ``k`` while depositing, None to keep the last."""
        if k - self.sent_k < self.interval_n:
            return None
        target = self._target(k)
        if abs(target - self.sent) <= FLOW_STEP * self.rate:
            return None
        self.sent, self.sent_k = target, k
        return target


class RobotNode(LifecycleNode):
    """See the module docstring. Parameters: backend, host, servo (table), home_deg, tool_T,
    sim_clock (twin backends: the clock file shared with the extruder emulator), state_hz
    (100), extruder (node name), supervisor (node name), extruder_fresh_s (0.05: max age of the
    extruder state), switch_margin_s (0.1: time allowed for a switch-on to show), sync_flow
    (true: scale the extrusion rate with the arm's planned speed)."""

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
        self.fresh_s = float(p.get("extruder_fresh_s", 0.05))
        self.margin_s = float(p.get("switch_margin_s", 0.1))
        self.sync_flow = bool(p.get("sync_flow", True))
        self._switches: queue.Queue[tuple[str, float]] = queue.Queue()
        self.state_period = 1.0 / float(p.get("state_hz", 100.0))
        self.alive: set[str] = set()
        self.estopped = ""
        self.estop_t = 0.0  # s since the epoch of the latched e-stop
        self.plan: StreamPlan | None = None
        self.job_id = ""
        self.stream: ServoStream | None = None
        self.mode = "idle"
        self.stop_reason, self.stop_t = "", 0.0
        self.waypoint = -1
        self._ext: ExtruderState | None = None
        self._ext_t = 0.0
        self.max_age = 0.0  # s, oldest extruder state the guard saw in the current stream
        self._motion_lock = threading.Lock()
        self._motion: threading.Thread | None = None
        self._abort_move = threading.Event()
        self._in_motion = threading.Event()
        self._seq = 0

    def on_activate(self) -> None:
        assert self.bus is not None
        self.bus.subscribe(self.extruder_name, "state", ExtruderState, self._on_extruder)
        self.bus.subscribe("estop", "estop", EStop, self._on_estop)
        self.bus.watch_presence(self._on_presence)
        self.bus.serve(self._on_command)
        self.spawn(self._publish_state, "state")
        self.spawn(self._switcher, "switcher")

    def _switcher(self) -> None:
        """Send extruder switch commands off the servo thread (a request takes a few ms)."""
        while not self.stopping.is_set():
            try:
                verb, rate = self._switches.get(timeout=0.2)
            except queue.Empty:
                continue
            if self.bus is not None:
                reply = self.bus.request(self.extruder_name, Command.make(verb, rate=rate), 1.0)
                if not reply.ok:
                    log.warning("extruder %s refused: %s", verb, reply.reason)

    def on_deactivate(self) -> None:
        self._halt("robot node shutting down")

    def on_shutdown(self) -> None:
        if self._motion is not None:
            self._motion.join(2.0)
        self.driver.close()

    # -- inputs ----------------------------------------------------------------------------
    def _on_extruder(self, msg: ExtruderState) -> None:
        self._ext, self._ext_t = msg, time.monotonic()

    def _on_presence(self, node: str, alive: bool) -> None:
        if alive:
            self.alive.add(node)
            return
        self.alive.discard(node)
        if node in (self.extruder_name, self.supervisor_name):
            self._halt(f"{node} process lost")

    def _on_estop(self, msg: EStop) -> None:
        self.estopped = f"e-stop from {msg.source}" + (f": {msg.reason}" if msg.reason else "")
        self.estop_t = time.time()
        self._halt(self.estopped)

    def _halt(self, reason: str) -> None:
        stream = self.stream
        if stream is not None:
            stream.stop(reason)
        self._abort_move.set()

    # -- interlocks ------------------------------------------------------------------------
    def _guard_factory(self, plan: StreamPlan, start: int, lead_s: float) -> Any:
        must = MustRun(plan.extrude, self._lead_samples(lead_s, plan),
                       self._latency_samples(self.margin_s, plan), start)

        def guard(k: int) -> str:
            if self.estopped:
                return self.estopped
            if self.extruder_name not in self.alive:
                return f"{self.extruder_name} process lost"
            if self.supervisor_name not in self.alive:
                return f"{self.supervisor_name} process lost"
            if must(k):
                ext, age = self._ext, time.monotonic() - self._ext_t
                if age > self.max_age:
                    self.max_age = age
                if ext is None or age > self.fresh_s:
                    return f"no extruder state for {age * 1000:.0f} ms"
                if ext.fault:
                    return f"extruder fault {ext.fault:#x}: {ext.detail}"
                if not ext.running:
                    return "extruder not running where the trajectory deposits"
            return ""

        return guard

    def _lead_samples(self, lead_s: float, plan: StreamPlan) -> int:
        """Servo samples spanning the lead ``lead_s``: it compensates the extruder's flow
        response, which runs on the twin's clock (the emulated extruder is scaled with it; the
        real cell has time_scale 1), so it is simulated time: samples times dt."""
        return round(lead_s / plan.dt)

    def _latency_samples(self, seconds: float, plan: StreamPlan) -> int:
        """Servo samples spanning ``seconds`` of wall time: the switch command's latency (bus,
        Modbus, the next state) is wall-clock, and a fast twin runs more samples per second."""
        return round(seconds * self.servo.time_scale / plan.dt)

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
            self.estopped = ""
            return Reply.done()
        if verb == "status":
            return Reply.done(estopped=self.estopped, estop_t=self.estop_t, mode=self.mode,
                              job_id=self.job_id, stop_reason=self.stop_reason,
                              stop_t=self.stop_t, waypoint=self.waypoint)
        if verb == "load":
            if self._busy():
                return Reply.refuse("robot is busy; stop it first")
            plan = StreamPlan.load(Path(cmd.path), self.servo.dt, cmd.sha256)
            self.plan, self.job_id = plan, cmd.job_id
            self.reach = self._reach(Path(cmd.path).parent)
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

    def _reach(self, job_dir: Path | None) -> Any:
        """The planner's reachability model of this cell, gel filled as the job's plan
        filled it (``fit_gel`` on the job's toolpath), or the cell's own fill."""
        from planner.placement import fit_gel
        from planner.reach import Reach

        cell = self.cell
        if job_dir is not None and (job_dir / "toolpath.npz").is_file():
            from core.stages import Toolpath

            cell = fit_gel(cell, Toolpath.load(job_dir))
        return Reach(cell)

    def _safe_path(self, target: np.ndarray) -> tuple[StreamPlan | None, str]:
        """A servo plan from the current joints to ``target`` on a checked safe path
        (``planner.entry.safe_move``), or None and the reason there is none; None and ""
        when the robot is already there."""
        from planner import entry

        q0 = np.asarray(self.driver.joints(), dtype=float)
        if np.abs(q0 - target).max() < 1e-4:
            return None, ""
        if self.reach is None:
            self.reach = self._reach(None)
        reach = self.reach
        move = entry.safe_move(reach, q0, target, entry.safe_heights(reach), tolerate_start=True)
        if not move.ok:
            return None, f"no safe path: {move.reason}"
        timing = entry.time_move(reach, move)
        dt = self.servo.dt
        # hold the target a little at the end: the servo (lookahead) settles onto it
        hold = np.ceil(max(0.2, 2.0 * self.servo.lookahead_s) / dt) * dt
        tool_T = self.plan.tool_T if self.plan is not None else self.cell.tool.tool_T
        return StreamPlan.of_path(dt, timing.t, move.q, tool_T, hold), ""

    def _start_move(self, cmd: Command) -> Reply:
        to = cmd.arg("to", "home")
        if to == "home":
            target = self.home
        elif to == "sample":
            if self.plan is None:
                return Reply.refuse("no trajectory loaded")
            k = int(cmd.arg("sample", 0))
            if not 0 <= k < self.plan.samples:
                return Reply.refuse(f"sample {k} outside the trajectory")
            target = self.plan.q_at(k)
        else:
            return Reply.refuse(f"unknown move target '{to}'")
        path, why = self._safe_path(np.asarray(target, dtype=float))
        if why:
            return Reply.refuse(why)
        self._abort_move.clear()

        def guard(k: int) -> str:
            if self.estopped:
                return self.estopped
            return "move interrupted" if self._abort_move.is_set() else ""

        def run() -> None:
            self.mode = "moving"
            log.info("move of %s to %s (%d servo samples)", cmd.job_id, to,
                     0 if path is None else path.samples)
            ok, why = False, "move interrupted"
            try:
                if path is None:
                    ok = not self._abort_move.is_set()
                else:
                    result = ServoStream(self.driver, path, 0, guard).run()
                    ok, why = result.done, result.reason or why
            except Exception as exc:  # the end event must go out whatever happened
                log.exception("move failed")
                why = f"move failed: {exc}"
            finally:
                self.mode = "idle" if ok else "stopped"
                self._in_motion.clear()
            log.info("move of %s to %s %s", cmd.job_id, to, "done" if ok else why)
            self._event(StreamEvent(cmd.job_id, "moved" if ok else "stopped",
                                    "" if ok else why, -1, time.time()))

        self._in_motion.set()
        self._motion = self.spawn(run, "move")
        return Reply.done()

    def _start_stream(self, cmd: Command) -> Reply:
        plan = self.plan
        if plan is None or cmd.job_id != self.job_id:
            return Reply.refuse(f"trajectory of job '{cmd.job_id}' is not loaded")
        start = int(cmd.arg("start", 0))
        K = plan.samples
        end = min(int(cmd.arg("end", K)), K)
        if not start < end:
            return Reply.refuse(f"empty stream: start {start}, end {end}")
        after = int(cmd.arg("after_waypoint", -1))
        lead_s = float(cmd.arg("lead_s", 0.0))
        if cmd.arg("rate") is None:  # the job's set-point: the supervisor reads it from the job
            return Reply.refuse("stream needs the job's extruder set-point (rate)")
        rate = float(cmd.arg("rate"))
        full_guard = self._guard_factory(plan, start, lead_s)

        def guard(k: int) -> str:
            return END if k >= end else full_guard(k)

        lead_n = self._lead_samples(lead_s, plan)

        def cmd_on(k: int) -> bool:
            # switch only for samples this stream sends (the part after ``end`` comes later)
            return plan.extrude_at(min(k + lead_n, end - 1))

        switched = {"on": cmd_on(start)}
        flow = FlowSync(plan, rate, lead_n, end, self._latency_samples(FLOW_INTERVAL_S, plan),
                        start) if self.sync_flow else None

        def on_sample(k: int) -> None:
            # Lead compensation on the servo clock: switch lead_n samples ahead.
            on = cmd_on(k)
            if on != switched["on"]:
                switched["on"] = on
                self._switches.put(("start", flow.switch_on(k) if flow else rate) if on
                                   else ("stop", rate))
            elif on and flow is not None:
                change = flow(k)
                if change is not None:
                    self._switches.put(("set_rate", change))

        why = guard(start)
        if why:
            return Reply.refuse(why)
        assert self.bus is not None
        bus, job = self.bus, cmd.job_id

        def on_waypoint(i: int) -> None:
            self.waypoint = int(plan.wp_id[i])
            bus.publish("waypoint", WaypointReached(job, self.waypoint, int(plan.wp_layer[i]),
                                                    int(plan.wp_sample[i]), time.time()),
                        express=True)

        self.max_age = 0.0
        stream = ServoStream(self.driver, plan, start, guard, on_sample=on_sample,
                             on_waypoint=on_waypoint, after_waypoint=after)
        self.stream = stream
        self.stop_reason = ""

        def run() -> None:
            self.mode = "streaming"
            try:
                result = stream.run()
            except Exception as exc:  # the end event must go out whatever happened
                log.exception("stream failed")
                self.driver.servo_stop()
                result = StreamResult(False, f"stream failed: {exc}", stream.sample, time.time(),
                                      np.zeros(0))
            if result.reason == END:  # reached ``end``: a finished stream, not a stop
                result = StreamResult(True, "", result.last_sample, result.stop_t,
                                      result.periods)
            self.stop_reason, self.stop_t = result.reason, result.stop_t
            self.mode = "idle" if result.done else "stopped"
            if result.reason:
                log.warning("stream of %s stopped at sample %d: %s", job, result.last_sample,
                            result.reason)
            log.info("stream of %s: oldest extruder state while depositing %.0f ms", job,
                     self.max_age * 1000)
            self._in_motion.clear()
            self._event(StreamEvent(job, "done" if result.done else "stopped", result.reason,
                                    result.last_sample, result.stop_t))

        self._in_motion.set()
        self._motion = self.spawn(run, "stream")
        return Reply.done()

    # -- outputs ---------------------------------------------------------------------------
    def _event(self, ev: StreamEvent) -> None:
        if self.bus is not None:
            self.bus.publish("event", ev, express=True)

    def _publish_state(self) -> None:
        next_t = time.monotonic()
        while not self.stopping.is_set() and self.bus is not None:
            d = self.driver
            q, qd = np.degrees(d.joints()), np.degrees(d.joint_speeds())
            stream, plan = self.stream, self.plan
            self._seq += 1
            mode = "fault" if (not d.connected() or d.protective_stopped()) else self.mode
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
            next_t += self.state_period
            time.sleep(max(0.0, next_t - time.monotonic()))


def main(argv: Sequence[str] | None = None) -> int:
    """Process entry point."""
    return node_main(RobotNode, argv, "robot")


if __name__ == "__main__":
    raise SystemExit(main())
