"""How the supervisor prints one job: approach, prime, stream, follow, stop, check.

``PrintLoop._print`` takes a job that is ready (or paused, or interrupted): the robot node
loads and checks its trajectory, the arm goes home and to the start sample on its checked safe
path, the planned entry is streamed up to the first deposition sample, the screw is primed and
started ``lead_s`` ahead of deposition, and the trajectory is streamed (the robot node switches
the extruder on the servo clock) while ``_monitor`` records checkpoints and publishes progress.
A resume starts right after the last waypoint the robot's ledger holds (``print_ledger``). A
stream that stops early leaves the job paused, aborted or interrupted (``_stopped``); a stream
that ends is done only if ``print_check`` finds every waypoint printed once and the ink.
The supervisor node (``supervisor_node``) owns the state this mixin works on.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

from core.errors import InputError
from core.report import update_report
from core.status import JobState
from core.tolerance import tol
from mesp_cell.drivers.stream import StreamPlan, sha256_of
from mesp_cell.jobs import JobRecord
from mesp_cell.messages import Command
from mesp_cell.nodes import print_ledger
from mesp_cell.nodes.cell_steps import Stopped
from mesp_cell.nodes.ink_at_rest import RestTimer, add_rest_ink, deposition_s, rest_ink
from mesp_cell.nodes.print_check import check_print
from mesp_cell.nodes.stream_follow import StreamFollow
from mesp_cell.profiles import stale_reason
from mesp_cell.states import StreamEnd
from slicer.extrusion import ExtrusionProfile, load_job_profile

log = logging.getLogger("mesp.supervisor")


class PrintLoop(StreamFollow):
    """The print of one job, mixed into ``SupervisorNode`` (the steps on the nodes:
    ``cell_steps``; following a stream: ``stream_follow``)."""

    def _job_profile(self, job: JobRecord) -> ExtrusionProfile:
        """The profile ``job`` was sliced with, if it is the cell's active calibration."""
        profile = load_job_profile(Path(job.dir))
        why = stale_reason(profile, self.cell)
        if why:
            raise InputError(why, "re-submit the job to slice it with the active profile, or "
                             f"`mesp profile activate {Path(job.dir) / 'profile.toml'} --on "
                             f"{self.cell}`")
        return profile

    def _print(self, job: JobRecord) -> None:
        resume = job.state in (JobState.PAUSED, JobState.INTERRUPTED)
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
                self._add_rest_ink(job, deposition_s(plan, start, self.lead_s, max(stop, start)))
        with self._lock:
            self.current, self.request = job.id, ""
        while not self.events.empty():
            self.events.get_nowait()
        self.store.transition(job.id, JobState.PRINTING, "resumed" if resume else "",
                              expect=job.state)
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
                if ev.kind != StreamEnd.DONE:
                    raise Stopped(ev.reason or "stream stopped")
                start = first
            lead_n = round(self.lead_s / self.dt)
            # Starting acknowledges a latched watchdog/stall fault (e.g. left by a killed
            # extruder node); an e-stop is only cleared by the operator (`mesp estop --reset`).
            self._extruder("clear")
            on = plan.extrude_at(min(start + lead_n, plan.samples - 1))
            at_rest: RestTimer | None = None
            if on:
                self._extruder("start", rate=self.setpoint)
                # Lead and prime run on the extruder's (the twin's) clock; the switch-on must
                # also show in the extruder state (wall-clock latency) before the stream starts.
                wait = (self.lead_s + (0.0 if resume else self.prime_s)) / self.time_scale
                at_rest = RestTimer(self.sim_clock, self.time_scale)
                time.sleep(max(wait, min(self.lead_s, self.settle_s)))

            def started() -> None:
                # the screw ran at rest from its start until the robot took the stream,
                # counted on the flow's clock (the twin's simulated time)
                if at_rest is not None:
                    self._add_rest_ink(job, at_rest.seconds()
                                       - deposition_s(plan, start - 1, self.lead_s))

            ev = self._stream(job, plan, ext0, start, after, started=started)
            if ev.kind == StreamEnd.DONE:
                self._extruder("stop")
            self._drain(job.id)
            if ev.kind != StreamEnd.DONE:
                raise Stopped(ev.reason or "stream stopped")
            self._move(job.id, to="home")
            volume = self._volume(job, ext0)
            self.store.progress(job.id, 100.0, 0.0, volume)
            check = check_print(Path(job.dir), plan, volume, rest_ink(Path(job.dir)),
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
            self.store.transition(job.id, JobState.DONE)
        except Stopped as exc:
            self._stopped(job, plan, str(exc), ext0)
        finally:
            with self._lock:
                self.current, self.request = "", ""


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
                self.store.transition(job.id, JobState.PAUSED, "paused by the operator")
            elif req == "abort":  # aborted once out of the gel (or why it could not be)
                self.store.transition(job.id, JobState.ABORTED,
                                      f"aborted by the operator; {self._retract(job.id)}")
            else:
                self.store.transition(job.id, JobState.INTERRUPTED, reason)
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
                    and abs(ext.rate) <= 0.01 * max(self.setpoint, tol.floor)):
                return
            time.sleep(0.02)
        log.warning("the screw did not show at rest within %g s; the job's volume may miss "
                    "its last ink", timeout)


    def _add_rest_ink(self, job: JobRecord, seconds: float) -> None:
        """Add ``seconds`` of the extruder's clock at the set-point to the job's ink at rest."""
        add_rest_ink(Path(job.dir), self.setpoint * self.true_per_nominal * seconds)
