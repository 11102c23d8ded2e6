"""The robot node's streams: a job's trajectory from a start sample, its interlocks, its
extruder switches and its ledger.

``RobotStreams._start_stream`` streams the samples ``start`` .. ``end`` - 1 of the loaded
trajectory in the motion thread: before every servo sample the interlock guard (``interlock``:
e-stop, the extruder and supervisor present, the extruder running and delivering wherever the
trajectory deposits); the extruder switched ``lead_s`` ahead of every change of deposition on
the servo clock, its rate scaled with the planned speed (``flow_sync``), the switches sent off
the servo thread (``extruder_switch``); every deposition waypoint passed appended to the job's
ledger before it is published (``print_ledger``); the screw stopped with an arm that stops
early; the end published as a ``StreamEvent``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from mesp_cell.bus.session import Bus
from mesp_cell.drivers.robot_base import RobotDriver, ServoConfig
from mesp_cell.drivers.stream import ServoStream, StreamPlan, StreamResult
from mesp_cell.messages import Command, Reply, StreamEvent, WaypointReached
from mesp_cell.nodes.extruder_switch import Switcher
from mesp_cell.nodes.flow_sync import FLOW_INTERVAL_S, FlowSync
from mesp_cell.nodes.idle_pace import Pace
from mesp_cell.nodes.interlock import Interlock, MustRun
from mesp_cell.nodes.print_ledger import Ledger
from mesp_cell.states import RobotMode, StreamEnd

END = "\x00end"  # guard reason that ends a stream at its ``end`` sample (not a stop)

log = logging.getLogger("mesp.robot")


class RobotStreams:
    """Trajectory streams of ``RobotNode`` (which sets these in ``on_configure``)."""

    bus: Bus | None
    driver: RobotDriver
    servo: ServoConfig
    plan: StreamPlan | None
    job_id: str
    job_dir: Path | None
    margin_s: float
    sync_flow: bool
    switcher: Switcher
    interlock: Interlock
    stream: ServoStream | None
    mode: str
    stop_reason: str
    stop_t: float
    waypoint: int
    pace: Pace
    _in_motion: threading.Event
    _motion: threading.Thread | None

    spawn: Callable[[Any, str], threading.Thread]
    _event: Callable[[StreamEvent], None]
    _stop_screw: Callable[[str], None]

    def _guard_factory(self, plan: StreamPlan, start: int, lead_s: float) -> Any:
        must = MustRun(plan.extrude, self._lead_samples(lead_s, plan),
                       self._latency_samples(self.margin_s, plan), start)
        return self.interlock.guard(must)

    def _lead_samples(self, lead_s: float, plan: StreamPlan) -> int:
        """Servo samples spanning the lead ``lead_s``: it compensates the extruder's flow
        response, which runs on the twin's clock (the emulated extruder is scaled with it; the
        real cell has time_scale 1), so it is simulated time: samples times dt."""
        return round(lead_s / plan.dt)

    def _latency_samples(self, seconds: float, plan: StreamPlan) -> int:
        """Servo samples spanning ``seconds`` of wall time: the switch command's latency (bus,
        Modbus, the next state) is wall-clock, and a fast twin runs more samples per second."""
        return round(seconds * self.servo.time_scale / plan.dt)

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

        on0 = cmd_on(start)
        switched = {"on": on0, "rate": rate if on0 else 0.0}  # as the extruder was left
        flow = FlowSync(plan, rate, lead_n, end, self._latency_samples(FLOW_INTERVAL_S, plan),
                        start) if self.sync_flow else None
        job_dir = self.job_dir

        def switch(verb: str, new: float, sent: float) -> None:
            self.switcher.put(verb, sent, new - switched["rate"], job_dir)
            switched["rate"] = new

        def on_sample(k: int) -> None:
            # Lead compensation on the servo clock: switch lead_n samples ahead.
            on = cmd_on(k)
            if on != switched["on"]:
                switched["on"] = on
                if on:
                    r = flow.switch_on(k) if flow else rate
                    switch("start", r, r)
                else:
                    switch("stop", 0.0, rate)
            elif on and flow is not None:
                change = flow(k)
                if change is not None:
                    switch("set_rate", change, change)

        why = guard(start)
        if why:
            return Reply.refuse(why)
        assert self.bus is not None and self.job_dir is not None
        bus, job = self.bus, cmd.job_id
        ledger = Ledger(self.job_dir, fresh=False)
        ledger.stream(start, after)

        def on_waypoint(i: int) -> None:
            self.waypoint = int(plan.wp_id[i])
            ledger.waypoint(self.waypoint, int(plan.wp_sample[i]))
            bus.publish("waypoint", WaypointReached(job, self.waypoint, int(plan.wp_layer[i]),
                                                    int(plan.wp_sample[i]), time.time()),
                        express=True)

        stream = ServoStream(self.driver, plan, start, guard, on_sample=on_sample,
                             on_waypoint=on_waypoint, after_waypoint=after)
        self.stream = stream
        self.stop_reason = ""

        def run() -> None:
            self.mode = RobotMode.STREAMING
            self.pace.wake()
            try:
                result = stream.run()
            except Exception as exc:  # the end event must go out whatever happened
                log.exception("stream failed")
                self.driver.servo_stop()
                result = StreamResult(False, f"stream failed: {exc}", stream.sample, time.time(),
                                      np.zeros(0))
            if result.reason and result.reason != END:
                self._stop_screw(result.reason)  # the arm stopped: the screw stops with it
                ledger.stopped(result.last_sample)
            ledger.close()
            if result.reason == END:  # reached ``end``: a finished stream, not a stop
                result = StreamResult(True, "", result.last_sample, result.stop_t,
                                      result.periods)
            self.stop_reason, self.stop_t = result.reason, result.stop_t
            self.mode = RobotMode.IDLE if result.done else RobotMode.STOPPED
            if result.reason:
                log.warning("stream of %s stopped at sample %d: %s", job, result.last_sample,
                            result.reason)
            log.info("stream of %s: oldest extruder state while depositing %.0f ms", job,
                     self.interlock.max_age * 1000)
            self._in_motion.clear()
            self.pace.wake()
            kind = StreamEnd.DONE if result.done else StreamEnd.STOPPED
            self._event(StreamEvent(job, kind, result.reason, result.last_sample, result.stop_t))

        self._in_motion.set()
        self._motion = self.spawn(run, "stream")
        return Reply.done()
