"""The live state the console streams: the supervisor's progress joined with the robot's and
the extruder's states, and what the job was planned to use.

Bus callbacks (zenoh threads) only store the latest message; ``snapshot`` builds one JSON-ready
dict from them when the console sends (5 Hz, and at once on a new progress message), so the
100 Hz state topics cost nothing per message beyond an assignment.
"""

from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from core.status import JobState
from mesp_cell.drivers.stream import StreamPlan
from mesp_cell.messages import FAULT_ESTOP, FAULT_NAMES, ExtruderState, JobProgress, RobotState
from mesp_cell.planned_ink import planned_ink
from planner.plan_summary import PlanSummary


@dataclass(frozen=True)
class JobPlan:
    """What a job was planned to do, for progress by ink and the tracking error.

    Attributes:
        job_id: job. ink_mm3: toolpath volume to deposit (report.json, else width x height x
        length of the depositing segments). duration_s: planned printing time (0 = unknown).
        min_clearance_mm: the plan's smallest clearance (nan = not in the report).
        plan: the servo-sampled trajectory (None when it cannot be read).
    """

    job_id: str
    ink_mm3: float
    duration_s: float
    min_clearance_mm: float
    plan: StreamPlan | None


def load_job_plan(job_id: str, job_dir: Path, dt: float) -> JobPlan:
    """The planned ink, duration, clearance and trajectory of a job (what exists of them)."""
    duration, clearance = 0.0, float("nan")
    report = job_dir / "report.json"
    if report.is_file():
        try:
            summary = PlanSummary.of(json.loads(report.read_text()).get("plan", {}))
            duration = summary.duration_s if np.isfinite(summary.duration_s) else 0.0
            if summary.min_clearance_mm is not None:
                clearance = summary.min_clearance_mm
        except (OSError, ValueError, TypeError, AttributeError):
            pass
    stream = None
    traj = job_dir / "trajectory.npz"
    if traj.is_file():
        try:
            stream = StreamPlan.load(traj, dt)
            duration = duration or stream.samples * dt
        except Exception:  # a malformed trajectory only costs the tracking error
            stream = None
    return JobPlan(job_id, planned_ink(job_dir), duration, clearance, stream)


def _num(x: float) -> float | None:
    """JSON has no NaN: unknown numbers are null."""
    return None if x is None or not np.isfinite(x) else float(x)


class LiveState:
    """The latest bus messages and the current job's plan; thread-safe."""

    def __init__(self, dt: float = 0.002) -> None:
        self.dt = dt
        self._lock = threading.Lock()
        self.progress: JobProgress | None = None
        self.progress_seen = 0.0  # time.time() when the last progress arrived
        self.robot: RobotState | None = None
        self.extruder: ExtruderState | None = None
        self.alive: set[str] = set()
        self.plans: dict[str, JobPlan] = {}
        self.seq = 0  # +1 per progress message

    # -- bus callbacks (zenoh threads) -----------------------------------------------------
    def on_progress(self, msg: JobProgress) -> None:
        with self._lock:
            self.progress, self.progress_seen = msg, time.time()
            self.seq += 1

    def on_robot(self, msg: RobotState) -> None:
        self.robot = msg

    def on_extruder(self, msg: ExtruderState) -> None:
        self.extruder = msg

    def on_presence(self, node: str, alive: bool) -> None:
        with self._lock:
            (self.alive.add if alive else self.alive.discard)(node)

    # -- views -----------------------------------------------------------------------------
    def plan_of(self, job_id: str, job_dir: Path) -> JobPlan:
        """The job's plan, read once (a job's artifacts do not change once it prints)."""
        plan = self.plans.get(job_id)
        if plan is None or (plan.plan is None and (job_dir / "trajectory.npz").is_file()):
            plan = load_job_plan(job_id, job_dir, self.dt)
            self.plans = {job_id: plan}  # only the current job's is kept
        return plan

    def snapshot(self, job_of: Any) -> dict[str, Any]:
        """The streamed state; ``job_of(job_id)`` gives a job's ``JobRecord`` (or None): its
        state is the store's (the last progress message may be older than the job's end)."""
        with self._lock:
            prog, seen, alive, seq = self.progress, self.progress_seen, sorted(self.alive), \
                self.seq
        robot, ext = self.robot, self.extruder
        out: dict[str, Any] = {"type": "live", "t": time.time(), "seq": seq, "alive": alive}
        if ext is not None:
            out["extruder"] = {
                "rate_set": ext.rate_set, "rate": ext.rate, "running": ext.running,
                "connected": ext.connected, "fault": ext.fault, "detail": ext.detail,
                "faults": [n for bit, n in FAULT_NAMES.items() if ext.fault & bit],
                "estop": bool(ext.fault & FAULT_ESTOP), "pressure": None}
        if robot is not None:
            out["robot"] = {"mode": robot.mode, "job_id": robot.job_id, "sample": robot.sample,
                            "samples": robot.samples, "tcp": list(robot.tcp),
                            "connected": robot.connected,
                            "protective_stop": robot.protective_stop,
                            "stop_reason": robot.stop_reason}
        if prog is not None:
            job: dict[str, Any] = {
                "job_id": prog.job_id, "state": prog.state, "layer": prog.layer,
                "layers": prog.layers, "waypoint": prog.waypoint, "waypoints": prog.waypoints,
                "percent_time": prog.percent, "eta_s": prog.eta_s, "ink_mm3": prog.volume,
                "progress_t": prog.t, "received_t": seen}
            rec = job_of(prog.job_id)
            if rec is not None:
                job["state"] = rec.state
                if rec.state == JobState.DONE:
                    job.update(percent_time=100.0, eta_s=0.0, ink_mm3=rec.volume)
                plan = self.plan_of(prog.job_id, Path(rec.dir))
                job["ink_planned_mm3"] = _num(plan.ink_mm3) if plan.ink_mm3 > 0 else None
                job["percent_ink"] = (_num(min(100.0, 100.0 * prog.volume / plan.ink_mm3))
                                      if plan.ink_mm3 > 0 else None)
                job["planned_s"] = _num(plan.duration_s)
                job["min_clearance_mm"] = _num(plan.min_clearance_mm)
                if (plan.plan is not None and robot is not None and robot.job_id == prog.job_id
                        and 0 <= robot.sample < plan.plan.samples):
                    q_cmd = np.degrees(plan.plan.q_at(robot.sample))
                    job["tracking_error_deg"] = float(np.abs(np.subtract(robot.q, q_cmd)).max())
            out["job"] = job
        return out
