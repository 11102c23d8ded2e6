"""The supervisor: takes jobs from the store and sequences them through the cell.

submitted -> (slicer node) sliced -> (planner node) planned -> pre-flight (the robot node
loads and checks the trajectory; a refusal fails the job before anything moves) -> print:
home, approach the start sample (the robot node's checked safe path; sample 0 is home), stream
the planned entry (home, above the gel, plunge along the nozzle axis) up to the first deposition
sample, prime and start extrusion ``lead_s`` ahead of deposition
(lead compensation of the extruder's flow response), stream the trajectory (the robot node
switches the extruder ``lead_s`` ahead of every change of ``extrude``, on the servo clock),
record a checkpoint at every deposited waypoint, publish progress, stop the extruder, park.
A stream that stops early (node lost, fault, e-stop) leaves the job ``interrupted`` with its
checkpoint; ``resume`` restarts right after the last waypoint the robot's ledger holds (what it
printed, ``print_ledger``), whatever the supervisor saw before it was killed. A job is done only
when the ledger holds every deposition waypoint exactly once and the ink extruded for the part
is the toolpath's within ``VOLUME_TOLERANCE`` (``print_check``); otherwise it fails with why.
A fresh print waits in ``ready_check`` until the
operator confirms the tank (``ready``); an abort retracts the nozzle along its axis and goes
home on the robot's checked safe path. Commands (``supervisor/cmd``): ``pause``, ``resume``,
``abort``, ``ready`` (job_id); ``resume`` and ``ready`` are refused while an e-stop is latched.

The extrusion rate C and the set-point the extruder is commanded come from the profile the job
was sliced with (its ``profile.toml``); a job whose profile is not the cell's active
calibration (``mesp profile``) is refused before it is planned and again before it moves.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from core.errors import InputError
from core.report import read_report, update_report
from mesp_cell.drivers.stream import StreamPlan, sha256_of
from mesp_cell.jobs import JobRecord, JobStore
from mesp_cell.messages import (
    FAULT_ESTOP,
    Command,
    ExtruderState,
    JobProgress,
    Reply,
    RobotState,
    StreamEvent,
    WaypointReached,
)
from mesp_cell.nodes import print_ledger
from mesp_cell.nodes.lifecycle import LifecycleNode, node_main
from mesp_cell.nodes.print_check import check_print
from mesp_cell.profiles import stale_reason
from mesp_cell.step_timeouts import plan_timeout, slice_timeout
from slicer.extrusion import ExtrusionProfile, load_job_profile

log = logging.getLogger("mesp.supervisor")


#: The reason a planned job waits in ``ready_check`` (shown by ``mesp job list`` and the console).
READY_REASON = ("waits for the operator: remove the last part, check the gel level, then "
                "confirm the tank is ready")


class Stopped(Exception):
    """The print stopped early; ``args[0]`` is the reason."""


class SupervisorNode(LifecycleNode):
    """See the module docstring. Parameters: jobs_db, lead_s, prime_s, dt,
    time_scale (of the twin and the emulated extruder: ETA, lead and prime waits), settle_s,
    robot/extruder/slicer/planner (node names), slice_timeout_s, plan_timeout_s, move_timeout_s,
    poll_s."""

    def on_configure(self) -> None:
        p = self.params
        self.store = JobStore(Path(p["jobs_db"]))
        self.cell = self.bus_config.cell
        self.setpoint = 0.0  # mm^3/s the extruder is commanded for the current job
        self.true_per_nominal = 1.0  # C / set-point of the current job's profile
        self.lead_s = float(p.get("lead_s", 0.3))
        self.prime_s = float(p.get("prime_s", 0.5))
        self.dt = float(p.get("dt", 0.002))
        # The twin's speed-up; the emulated extruder runs on the same clock (ETA, lead, prime).
        self.time_scale = float(p.get("time_scale", 1.0))
        self.settle_s = float(p.get("settle_s", 0.05))  # wall s for a switch-on to show
        self.names = {k: p.get(k, k) for k in ("robot", "extruder", "slicer", "planner")}
        # 0 = sized to each job (mesp_cell.step_timeouts)
        self.timeouts = {"slice": float(p.get("slice_timeout_s", 0.0)),
                         "plan": float(p.get("plan_timeout_s", 0.0)),
                         "move": float(p.get("move_timeout_s", 120.0))}
        self.poll_s = float(p.get("poll_s", 0.1))
        self.alive: set[str] = set()
        self.events: queue.Queue[StreamEvent] = queue.Queue()
        self.waypoints: queue.Queue[WaypointReached] = queue.Queue()
        self.robot_state: RobotState | None = None
        self.extruder_state: ExtruderState | None = None
        self.current = ""
        self.request = ""  # "pause" | "abort" for the current job
        self.park = ""  # an aborted job whose nozzle the work loop retracts and parks home
        self._lock = threading.Lock()
        for job in self.store.query(self.cell, ("printing",)):
            self.store.transition(job.id, "interrupted", "supervisor restarted mid-print")
        self.store.unconfirm_all(self.cell)  # a new session confirms its first job itself

    def on_activate(self) -> None:
        assert self.bus is not None
        r = self.names["robot"]
        self.bus.subscribe(r, "event", StreamEvent, self.events.put)
        self.bus.subscribe(r, "waypoint", WaypointReached, self.waypoints.put)
        self.bus.subscribe(r, "state", RobotState, self._on_robot)
        self.bus.subscribe(self.names["extruder"], "state", ExtruderState, self._on_extruder)
        self.bus.watch_presence(self._on_presence)
        self.bus.serve(self._on_command)
        self.spawn(self._work, "work")

    def on_deactivate(self) -> None:
        with self._lock:
            if self.current:
                self.request = "shutdown"

    def on_shutdown(self) -> None:
        self.store.close()

    # -- inputs ----------------------------------------------------------------------------
    def _on_robot(self, msg: RobotState) -> None:
        self.robot_state = msg

    def _on_extruder(self, msg: ExtruderState) -> None:
        self.extruder_state = msg

    def _on_presence(self, node: str, alive: bool) -> None:
        (self.alive.add if alive else self.alive.discard)(node)

    def _estop_latched(self) -> str:
        """Why motion cannot start now because of a latched e-stop ("" if none)."""
        asked = time.time()
        reply = self._request(self.names["robot"], Command.make("status"), 2.0)
        why = str(reply.value("estopped", "")) if reply.ok else ""
        # the extruder's latch as of a state sent after the question (a reset just
        # confirmed shows in the next state, 10 ms later)
        end = time.monotonic() + 0.5
        while (self.extruder_state is not None and self.extruder_state.t < asked
               and time.monotonic() < end):
            time.sleep(0.01)
        ext = self.extruder_state
        if not why and ext is not None and ext.fault & FAULT_ESTOP:
            why = "extruder e-stop latched"
        return why

    def _on_command(self, cmd: Command) -> Reply:
        job = self.store.get(cmd.job_id)
        if job.cell != self.cell:
            return Reply.refuse(f"job {job.id} belongs to cell '{job.cell}', not '{self.cell}'")
        if cmd.verb in ("resume", "ready"):
            latched = self._estop_latched()
            if latched:
                return Reply.refuse(f"cannot {cmd.verb} job {job.id}: {latched}; clear it with "
                                    "`mesp estop --reset` once the cell is safe")
            if cmd.verb == "ready":
                self.store.confirm_ready(job.id, cmd.arg("who", "the operator"))
                return Reply.done(state="ready_check")
            self.store.request_resume(job.id)
            return Reply.done(state=job.state)
        if cmd.verb in ("pause", "abort"):
            with self._lock:
                # still printing: the print loop stops it (a job already paused while the loop
                # waits for its screw to settle is aborted below, like any paused job)
                if self.current == job.id and self.store.get(job.id).state == "printing":
                    self.request = cmd.verb
                    self._request(self.names["robot"], Command.make("stop", reason=cmd.verb), 2.0)
                    return Reply.done()
            if cmd.verb == "pause":
                why = self.store.check_transition(job, "paused")
                return Reply.refuse(why or f"job {job.id} is not printing")
            self.store.transition(job.id, "aborted", "aborted by the operator")
            if job.state in ("paused", "interrupted"):
                with self._lock:  # its nozzle may still be in the gel
                    self.park = job.id
            return Reply.done()
        return Reply.refuse(f"unknown supervisor command '{cmd.verb}'")

    # -- helpers ---------------------------------------------------------------------------
    def _request(self, node: str, cmd: Command, timeout: float = 5.0) -> Reply:
        assert self.bus is not None
        return self.bus.request(node, cmd, timeout)

    def _need(self, *nodes: str) -> str:
        missing = [self.names[n] for n in nodes if self.names[n] not in self.alive]
        return f"node(s) {', '.join(missing)} not running" if missing else ""

    def _wait_event(self, job_id: str, timeout: float) -> StreamEvent:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.names["robot"] not in self.alive:
                raise Stopped(f"{self.names['robot']} process lost")
            try:
                ev = self.events.get(timeout=0.05)
            except queue.Empty:
                continue
            if ev.job_id == job_id:
                return ev
        raise Stopped(f"robot did not finish within {timeout:g} s")

    def _check_request(self) -> None:
        """Raise ``Stopped`` if the operator paused or aborted the current job."""
        if self.request:
            raise Stopped(f"{self.request} requested")

    def _move(self, job_id: str, **args: Any) -> None:
        self._check_request()
        reply = self._request(self.names["robot"], Command.make("move", job_id, **args))
        if not reply.ok:
            raise Stopped(reply.reason)
        ev = self._wait_event(job_id, self.timeouts["move"])
        if ev.kind != "moved":
            raise Stopped(ev.reason or "move interrupted")

    def _extruder(self, verb: str, **args: Any) -> None:
        reply = self._request(self.names["extruder"], Command.make(verb, **args), 2.0)
        if not reply.ok:
            raise Stopped(f"extruder refused {verb}: {reply.reason}")

    # -- the work loop ---------------------------------------------------------------------
    def _work(self) -> None:
        waiting_logged = ""
        while not self.stopping.wait(self.poll_s):
            if self.park:
                self._park()
            job = self.store.next_pending(self.cell)
            if job is None:
                continue
            try:
                if job.state == "submitted":
                    self._stage(job, "slice", "sliced")
                elif job.state == "sliced":
                    self._job_profile(job)
                    self._stage(job, "plan", "planned")
                elif job.state == "planned":
                    self.store.transition(job.id, "ready_check", READY_REASON, expect="planned")
                    log.info("job %s waits for the operator to confirm the tank", job.id)
                else:
                    why = self._need("robot", "extruder")
                    if why:
                        if waiting_logged != job.id:
                            log.warning("job %s waits: %s", job.id, why)
                            waiting_logged = job.id
                        continue
                    self._print(job)
            except InputError as exc:
                self._fail(job.id, exc.one_line())
            except Exception as exc:  # a bug must fail the job visibly, not kill the loop
                log.exception("job %s", job.id)
                self._fail(job.id, f"{type(exc).__name__}: {exc}")

    def _park(self) -> None:
        """Retract the aborted job's nozzle along its axis out of the gel and go home."""
        with self._lock:
            job_id, self.park = self.park, ""
        self.store.note(job_id, self._retract(job_id))

    def _retract(self, job_id: str) -> str:
        """Move home on the robot's checked safe path (retract along the nozzle axis, transfer
        above the gel); returns what happened, for the job's history."""
        reply = self._request(self.names["robot"], Command.make("move", job_id, to="home"))
        if not reply.ok:
            return f"nozzle not retracted: {reply.reason}"
        try:
            ev = self._wait_event(job_id, self.timeouts["move"])
        except Stopped as exc:
            return f"nozzle not retracted: {exc}"
        if ev.kind != "moved":
            return f"nozzle not retracted: {ev.reason or 'move interrupted'}"
        return "nozzle retracted along its axis out of the gel and parked at home"

    def _fail(self, job_id: str, reason: str) -> None:
        try:
            self.store.transition(job_id, "failed", reason)
        except InputError:  # aborted by the operator meanwhile: that state stands
            log.info("job %s not failed (%s): %s", job_id, self.store.get(job_id).state, reason)

    def _job_profile(self, job: JobRecord) -> ExtrusionProfile:
        """The profile ``job`` was sliced with, if it is the cell's active calibration."""
        profile = load_job_profile(Path(job.dir))
        why = stale_reason(profile, self.cell)
        if why:
            raise InputError(why, "re-submit the job to slice it with the active profile, or "
                             f"`mesp profile activate {Path(job.dir) / 'profile.toml'} --on "
                             f"{self.cell}`")
        return profile

    def _stage(self, job: JobRecord, verb: str, next_state: str) -> None:
        node = self.names["slicer" if verb == "slice" else "planner"]
        if node not in self.alive:
            return
        reply = self._request_while_alive(
            node, Command.make(verb, job.id, model=job.model, job_file=job.job_file,
                               cell_file=job.cell_file, dir=job.dir),
            self._step_timeout(verb, job))
        if reply.ok:
            self.store.transition(job.id, next_state, expect=job.state)
        else:
            self.store.transition(job.id, "failed", f"{verb}: {reply.reason}")

    def _request_while_alive(self, node: str, cmd: Command, timeout: float) -> Reply:
        """``_request``, given up as soon as ``node`` leaves the bus (its process died or
        stopped on a dead worker): the job fails at once instead of after ``timeout``."""
        stopped = Reply.refuse(f"the {node} node stopped while working on the job (see its "
                               "log; the launcher restarts it)")
        box: list[Reply] = []
        start = time.monotonic()
        asker = threading.Thread(target=lambda: box.append(self._request(node, cmd, timeout)),
                                 name=f"{self.name}-ask-{node}", daemon=True)
        asker.start()
        while asker.is_alive():
            asker.join(0.1)
            if asker.is_alive() and node not in self.alive:
                return stopped
        early = time.monotonic() - start < 0.9 * timeout
        # a query dropped unanswered long before the timeout: the node's worker died with it
        return stopped if early and not box[0].ok and "no reply" in box[0].reason else box[0]

    def _step_timeout(self, verb: str, job: JobRecord) -> float:
        """The launch's fixed timeout for ``verb`` if it sets one, else one sized to the job
        (``mesp_cell.step_timeouts``; an unreadable model fails the job here)."""
        if self.timeouts.get(verb):
            return self.timeouts[verb]
        if verb == "slice":
            return slice_timeout(Path(job.model), Path(job.job_file) if job.job_file else None)
        return plan_timeout(Path(job.dir))

    def _print(self, job: JobRecord) -> None:
        resume = job.state in ("paused", "interrupted")
        traj = Path(job.dir) / "trajectory.npz"
        if not traj.is_file():
            raise InputError(f"job {job.id} has no trajectory.npz", "re-submit the job")
        profile = self._job_profile(job)
        self.setpoint = profile.setpoint_mm3_s
        self.true_per_nominal = profile.rate_mm3_s / profile.setpoint_mm3_s
        plan = StreamPlan.load(traj, self.dt)
        digest = sha256_of(traj)
        robot = self.names["robot"]
        reply = self._request(robot, Command.make("load", job.id, path=str(traj), sha256=digest,
                                                  fresh=not resume))
        if not reply.ok:
            raise InputError(f"pre-flight: {reply.reason}", "fix the job and re-submit it")
        self.store.set_sizes(job.id, plan.layers, int(plan.wp_id.size), plan.samples)
        start, after = 0, -1
        if resume:  # right after the last waypoint the robot printed
            after, start = self._checkpoint(job, plan)
            start = max(start, 0)
            if after >= 0:  # re-traced up to the stop, and the screw's lead past it
                stop = print_ledger.read(Path(job.dir)).stop
                self._add_rest_ink(job, self._deposition_s(plan, start, max(stop, start)))
        with self._lock:
            self.current, self.request = job.id, ""
        while not self.events.empty():
            self.events.get_nowait()
        self.store.transition(job.id, "printing", "resumed" if resume else "", expect=job.state)
        ext0 = self.extruder_state.volume if self.extruder_state else 0.0
        try:
            if not resume:
                self._move(job.id, to="home")
            # the robot node moves on a checked safe path: out of the gel along the nozzle
            # axis, above it, and into it along the target sample's axis (sample 0 is home)
            self._move(job.id, to="sample", sample=start)
            first = plan.first_extruding()
            # a fault the controller latched (a watchdog left by a lost link or a killed
            # extruder node) is acknowledged before anything streams: the robot stops even a
            # travel move on an extruder fault
            self._extruder("clear")
            if start < first:
                # the planned entry (home -> plunge to the first waypoint) deposits nothing:
                # stream it, then lead and prime at rest at the first deposition sample
                ev = self._stream(job, plan, ext0, start, after, end=first)
                self._drain(job.id)
                if ev.kind != "done":
                    raise Stopped(ev.reason or "stream stopped")
                start = first
            lead_n = round(self.lead_s / self.dt)
            # Starting acknowledges a latched watchdog/stall fault (e.g. left by a killed
            # extruder node); an e-stop is only cleared by the operator (`mesp estop --reset`).
            self._extruder("clear")
            on = plan.extrude_at(min(start + lead_n, plan.samples - 1))
            t_on = -1.0
            if on:
                self._extruder("start", rate=self.setpoint)
                # Lead and prime run on the extruder's (the twin's) clock; the switch-on must
                # also show in the extruder state (wall-clock latency) before the stream starts.
                wait = (self.lead_s + (0.0 if resume else self.prime_s)) / self.time_scale
                t_on = time.monotonic()
                time.sleep(max(wait, min(self.lead_s, self.settle_s)))

            def started() -> None:
                # the screw ran at rest from its start until the robot took the stream (the
                # request's wall time counts time_scale times over on a fast twin's clock)
                if t_on >= 0:
                    self._add_rest_ink(job, (time.monotonic() - t_on) * self.time_scale
                                       - self._deposition_s(plan, start - 1))

            ev = self._stream(job, plan, ext0, start, after, started=started)
            if ev.kind == "done":
                self._extruder("stop")
            self._drain(job.id)
            if ev.kind != "done":
                raise Stopped(ev.reason or "stream stopped")
            self._move(job.id, to="home")
            volume = self._volume(job, ext0)
            self.store.progress(job.id, 100.0, 0.0, volume)
            check = check_print(Path(job.dir), plan, volume, self._rest_ink(job),
                                self.setpoint * self.true_per_nominal * self.lead_s,
                                self.true_per_nominal)
            update_report(Path(job.dir), {"print": {
                "cell": self.cell, "volume_mm3": volume, **check.report(),
                "profile": {"name": profile.name, "sha256": profile.sha256,
                            "rate_mm3_s": profile.rate_mm3_s,
                            "setpoint_mm3_s": profile.setpoint_mm3_s,
                            "calibrated": profile.calibrated}}})
            if not check.ok:
                raise InputError(check.reason, check.fix)
            self.store.transition(job.id, "done")
        except Stopped as exc:
            self._stopped(job, plan, str(exc), ext0)
        finally:
            with self._lock:
                self.current, self.request = "", ""

    def _stream(self, job: JobRecord, plan: StreamPlan, ext0: float, start: int, after: int,
                end: int | None = None,
                started: Callable[[], None] | None = None) -> StreamEvent:
        """Stream samples ``start`` .. ``end`` - 1 (to the end by default) and follow it;
        ``started`` is called as soon as the robot took the stream."""
        self._check_request()
        args: dict[str, Any] = {"start": start, "after_waypoint": after, "lead_s": self.lead_s,
                                "rate": self.setpoint}
        if end is not None:
            args["end"] = end
        reply = self._request(self.names["robot"], Command.make("stream", job.id, **args))
        if not reply.ok:
            raise Stopped(reply.reason)
        if started is not None:
            started()
        return self._monitor(job, plan, ext0)

    def _checkpoint(self, job: JobRecord, plan: StreamPlan) -> tuple[int, int]:
        """(waypoint, sample) the robot's ledger last printed (-1, -1: nothing yet), recorded
        as the job's checkpoint."""
        waypoint, sample = print_ledger.read(Path(job.dir)).last
        if waypoint >= 0:
            i = int(np.searchsorted(plan.wp_id, waypoint))
            self.store.checkpoint(job.id, int(plan.wp_layer[i]), waypoint, sample)
        return waypoint, sample

    def _rest_ink(self, job: JobRecord) -> float:
        """mm^3 of the job's ink that is not the toolpath's, so far. The screw runs ``lead_s``
        ahead of the arm, so a stream's screw time is its deposition time plus the time it
        ran at rest before the stream (purge, lead), less the deposition in the lead after
        its first sample (the lead paid back), plus, when it stops early, the deposition in
        the lead after the stop; a resume re-traces from the last printed waypoint to the
        stop. Each is counted here (``_add_rest_ink``) as it happens."""
        return float(read_report(Path(job.dir)).get("ink_at_rest", {}).get("mm3", 0.0))

    def _add_rest_ink(self, job: JobRecord, seconds: float) -> None:
        """Add ``seconds`` of the extruder's clock at the set-point to the job's ink not for
        the toolpath (``_rest_ink``)."""
        ink = self.setpoint * self.true_per_nominal * seconds
        update_report(Path(job.dir), {"ink_at_rest": {"mm3": self._rest_ink(job) + ink}})

    def _deposition_s(self, plan: StreamPlan, k: int, stop: int | None = None) -> float:
        """s of deposition after servo sample ``k`` up to ``lead_s`` past ``stop`` (default
        ``k``): the screw runs that far ahead of the arm (the robot switches it ``lead_s``
        ahead)."""
        last = k if stop is None else stop
        idx = np.arange(k + 1, min(last + 1 + round(self.lead_s / self.dt), plan.samples))
        return float(np.count_nonzero(plan.extrude[idx])) * self.dt if idx.size else 0.0

    def _stopped(self, job: JobRecord, plan: StreamPlan, reason: str, ext0: float) -> None:
        try:
            self._request(self.names["extruder"], Command.make("stop"), 1.0)
            self._request(self.names["robot"], Command.make("stop", reason=reason), 1.0)
        finally:
            self._drain(job.id)
            self._checkpoint(job, plan)
            self.store.progress(job.id, self.store.get(job.id).percent, 0.0,
                                self._volume(job, ext0))
            req = self.request
            if req == "pause":
                self.store.transition(job.id, "paused", "paused by the operator")
            elif req == "abort":  # aborted once out of the gel (or why it could not be)
                self.store.transition(job.id, "aborted",
                                      f"aborted by the operator; {self._retract(job.id)}")
            else:
                self.store.transition(job.id, "interrupted", reason)
            log.warning("job %s stopped: %s", job.id, reason)
            # the screw delivers a little more after the stop: counted before the job goes on
            self._settle_screw()
            self.store.progress(job.id, self.store.get(job.id).percent, 0.0,
                                self._volume(job, ext0))

    def _settle_screw(self, timeout: float = 5.0) -> None:
        """Wait until a fresh extruder state shows the screw at rest: it keeps delivering
        (its flow response) after a stop, and a killed extruder node comes back within the
        timeout; the job's volume then holds that ink too."""
        asked = time.time()
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            ext = self.extruder_state
            if (ext is not None and ext.t > asked and ext.connected and not ext.running
                    and abs(ext.rate) <= 0.01 * max(self.setpoint, 1e-9)):
                return
            time.sleep(0.02)
        log.warning("the screw did not show at rest within %g s; the job's volume may miss "
                    "its last ink", timeout)

    def _volume(self, job: JobRecord, ext0: float) -> float:
        """mm^3 extruded: the controller's totaliser (nominal) times the profile's C per
        set-point (what weighing found it really delivers)."""
        now = self.extruder_state.volume if self.extruder_state else ext0
        return job.volume + max(0.0, now - ext0) * self.true_per_nominal

    def _drain(self, job_id: str) -> None:
        """Record the waypoints still queued (they may trail the stream's end event)."""
        time.sleep(0.05)
        last: WaypointReached | None = None
        while not self.waypoints.empty():
            wp = self.waypoints.get_nowait()
            if wp.job_id == job_id:
                last = wp
        if last is not None:
            self.store.checkpoint(job_id, last.layer, last.waypoint, last.sample)

    def _lost_end(self, job_id: str, asked: float) -> StreamEvent | None:
        """The end of ``job_id``'s stream if its event was lost on the bus: the robot's state
        shows it not streaming well after the stream was asked for (``asked``, s since the
        epoch); its ``status`` then says how it ended."""
        rs = self.robot_state
        if (rs is None or rs.t < asked + 1.0 or rs.job_id != job_id
                or rs.mode not in ("idle", "stopped")):
            return None
        reply = self._request(self.names["robot"], Command.make("status"), 1.0)
        if not reply.ok or reply.value("mode") not in ("idle", "stopped"):
            return None
        log.warning("the end of the stream of %s did not arrive; the robot is %s", job_id,
                    reply.value("mode"))
        why = str(reply.value("stop_reason", ""))
        return StreamEvent(job_id, "done" if reply.value("mode") == "idle" else "stopped",
                           why, rs.sample, float(reply.value("stop_t", time.time())))

    def _monitor(self, job: JobRecord, plan: StreamPlan, ext0: float) -> StreamEvent:
        """Follow the stream (checkpoints, progress) until it ends. The robot node switches
        the extruder on the servo clock."""
        assert self.bus is not None
        K = plan.samples
        last_report = 0.0
        eta_of = EtaEstimate(self.time_scale / self.dt)
        layer = max(job.layer, 0)
        wp_last = job.waypoint
        asked = time.time()
        while True:
            if self.names["robot"] not in self.alive:
                raise Stopped(f"{self.names['robot']} process lost")
            lost = self._lost_end(job.id, asked)
            if lost is not None:
                return lost
            if self.names["extruder"] not in self.alive:
                self._request(self.names["robot"], Command.make("stop", reason="extruder lost"),
                              1.0)
            if self.request:
                self._request(self.names["robot"], Command.make("stop", reason=self.request),
                              1.0)
            try:
                ev = self.events.get(timeout=0.01)
                if ev.job_id == job.id and ev.kind in ("done", "stopped"):
                    return ev
            except queue.Empty:
                pass
            last: WaypointReached | None = None
            while not self.waypoints.empty():
                wp = self.waypoints.get_nowait()
                if wp.job_id == job.id:
                    last = wp
            if last is not None:
                self.store.checkpoint(job.id, last.layer, last.waypoint, last.sample)
                layer, wp_last = max(last.layer, 0), last.waypoint
            rs = self.robot_state
            s = rs.sample if rs is not None and rs.job_id == job.id else -1
            now = time.monotonic()
            if now - last_report > 0.2 and s >= 0:
                last_report = now
                percent = 100.0 * (s + 1) / K
                eta = eta_of(now, s, K - 1 - s)
                vol = self._volume(job, ext0)
                self.store.progress(job.id, percent, eta, vol)
                self.bus.publish("progress", JobProgress(
                    job.id, "printing", layer, plan.layers, wp_last, int(plan.wp_id.size),
                    percent, eta, vol, time.time()))


class EtaEstimate:
    """Time left from the pace the stream keeps, not the pace it was asked for.

    A twin that cannot keep its time scale (MuJoCo at 80x on 2 cores ran at ~64x) would make
    ``remaining x dt / time_scale`` promise too early an end. The pace is measured over the
    last ``WINDOW_S`` of wall time, once at least ``MIN_SPAN_S`` of it is seen; before that,
    and while no sample advances, the nominal pace stands.

    Args:
        nominal: samples per wall second asked for (``time_scale / dt``).
    """

    WINDOW_S = 30.0
    MIN_SPAN_S = 2.0

    def __init__(self, nominal: float) -> None:
        self.nominal = nominal
        self._seen: deque[tuple[float, int]] = deque()

    def __call__(self, now: float, sample: int, remaining: int) -> float:
        """Seconds of wall time left, with ``sample`` reached at ``now`` (monotonic s)."""
        seen = self._seen
        seen.append((now, sample))
        while len(seen) > 2 and now - seen[1][0] >= self.WINDOW_S:
            seen.popleft()
        t0, s0 = seen[0]
        pace = self.nominal
        if now - t0 >= self.MIN_SPAN_S and sample > s0:
            pace = (sample - s0) / (now - t0)
        return max(remaining, 0) / pace


def main(argv: Sequence[str] | None = None) -> int:
    """Process entry point."""
    return node_main(SupervisorNode, argv, "supervisor")


if __name__ == "__main__":
    raise SystemExit(main())
