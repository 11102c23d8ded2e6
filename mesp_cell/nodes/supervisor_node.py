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
How one job prints is ``print_loop``. A fresh print waits in ``ready_check`` until the
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
from collections.abc import Sequence
from pathlib import Path

from core.errors import InputError
from core.status import JobState
from mesp_cell.drivers.sim_clock import SimClock
from mesp_cell.jobs import JobRecord, JobStore
from mesp_cell.messages import (
    FAULT_ESTOP,
    Command,
    ExtruderState,
    Reply,
    RobotState,
    StreamEvent,
    WaypointReached,
)
from mesp_cell.nodes.lifecycle import LifecycleNode, node_main
from mesp_cell.nodes.print_loop import PrintLoop
from mesp_cell.step_timeouts import plan_timeout, slice_timeout

log = logging.getLogger("mesp.supervisor")


#: The reason a planned job waits in ``ready_check`` (shown by ``mesp job list`` and the console).
READY_REASON = ("waits for the operator: remove the last part, check the gel level, then "
                "confirm the tank is ready")


class SupervisorNode(PrintLoop, LifecycleNode):
    """See the module docstring (the print of one job: ``PrintLoop``). Parameters: jobs_db,
    lead_s, prime_s, dt, time_scale (of the twin and the emulated extruder: ETA, lead and
    prime waits), sim_clock (the twin's shared clock file: the ink at rest in simulated
    time; none on the real cell), settle_s, robot/extruder/slicer/planner (node names),
    slice_timeout_s, plan_timeout_s, move_timeout_s, poll_s."""

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
        # the twin's shared clock, which the emulated extruder's flow runs on (only read here)
        path = p.get("sim_clock") or None
        self.sim_clock = SimClock(self.time_scale, path) if path else None
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
            self.store.transition(job.id, JobState.INTERRUPTED, "supervisor restarted mid-print")
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
        if self.sim_clock is not None:
            self.sim_clock.close()

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
        # confirmed shows in the next state, at most an idle period later)
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
                if self.current == job.id and self.store.get(job.id).state == JobState.PRINTING:
                    self.request = cmd.verb
                    self._request(self.names["robot"], Command.make("stop", reason=cmd.verb), 2.0)
                    return Reply.done()
            if cmd.verb == "pause":
                why = self.store.check_transition(job, JobState.PAUSED)
                return Reply.refuse(why or f"job {job.id} is not printing")
            self.store.transition(job.id, JobState.ABORTED, "aborted by the operator")
            if job.state in (JobState.PAUSED, JobState.INTERRUPTED):
                with self._lock:  # its nozzle may still be in the gel
                    self.park = job.id
            return Reply.done()
        return Reply.refuse(f"unknown supervisor command '{cmd.verb}'")

    # -- helpers ---------------------------------------------------------------------------

    def _need(self, *nodes: str) -> str:
        missing = [self.names[n] for n in nodes if self.names[n] not in self.alive]
        return f"node(s) {', '.join(missing)} not running" if missing else ""





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
                if job.state == JobState.SUBMITTED:
                    self._stage(job, "slice", JobState.SLICED)
                elif job.state == JobState.SLICED:
                    self._job_profile(job)
                    self._stage(job, "plan", JobState.PLANNED)
                elif job.state == JobState.PLANNED:
                    self.store.transition(job.id, JobState.READY_CHECK, READY_REASON,
                                          expect=JobState.PLANNED)
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

    def _fail(self, job_id: str, reason: str) -> None:
        try:
            self.store.transition(job_id, JobState.FAILED, reason)
        except InputError:  # aborted by the operator meanwhile: that state stands
            log.info("job %s not failed (%s): %s", job_id, self.store.get(job_id).state, reason)


    def _stage(self, job: JobRecord, verb: str, next_state: JobState) -> None:
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
            self.store.transition(job.id, JobState.FAILED, f"{verb}: {reply.reason}")

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














def main(argv: Sequence[str] | None = None) -> int:
    """Process entry point."""
    return node_main(SupervisorNode, argv, "supervisor")


if __name__ == "__main__":
    raise SystemExit(main())
