"""The recorder node: each print's telemetry into ``<job dir>/telemetry.mcap``.

A recording opens at the first robot state that names a job (the approach move, then the
print stream) and closes at the print stream's end (event done or stopped), or ``idle_s``
after the last state that named it. A job resumed later gets ``telemetry-2.mcap`` and so
on. Bus callbacks only queue the messages; one thread writes
(``mesp_cell.telemetry.JobRecorder``), so a slow disk never blocks the bus. Parameters:
``jobs_db`` (the job store, for the job directory), ``record_hz``, ``max_mb``, ``idle_s``,
``nice`` (15: the process yields the CPU to the servo loop).
"""

from __future__ import annotations

import logging
import os
import queue
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from mesp_cell.jobs import JobStore
from mesp_cell.messages import (
    EStop,
    ExtruderState,
    JobProgress,
    RobotState,
    StreamEvent,
)
from mesp_cell.nodes.lifecycle import LifecycleNode, NodeStartError, node_main
from mesp_cell.states import RobotMode, StreamEnd
from mesp_cell.telemetry import JobRecorder

log = logging.getLogger("mesp.recorder")
SOURCES: tuple[tuple[str, str, type], ...] = (
    ("robot", "state", RobotState), ("extruder", "state", ExtruderState),
    ("supervisor", "progress", JobProgress), ("robot", "event", StreamEvent),
    ("estop", "estop", EStop),
)  # not robot/waypoint: up to 400 events/s at a high time scale, and progress has the waypoint


class RecorderNode(LifecycleNode):
    """See the module docstring."""

    def on_configure(self) -> None:
        db = self.params.get("jobs_db", "")
        if not db:
            raise NodeStartError("no jobs_db parameter", "name the job store in the launch file")
        # a logger must never take the CPU from the servo loop on a small machine: lowest
        # useful priority, and the imports a job's first state needs done now, not then
        os.nice(int(self.params.get("nice", 15)))
        import mcap.writer  # noqa: F401

        from planner.trajectory import Trajectory  # noqa: F401

        self.store = JobStore(Path(db))
        self.record_hz = float(self.params.get("record_hz", 20.0))
        self.max_mb = float(self.params.get("max_mb", 1024.0))
        self.idle_s = float(self.params.get("idle_s", 5.0))
        self.inbox: queue.Queue[Any] = queue.Queue(maxsize=200_000)
        self.recorder: JobRecorder | None = None
        self.job_id = ""
        self.finished = ""  # the job whose stream ended last
        self.last_seen = 0.0

    def on_activate(self) -> None:
        assert self.bus is not None
        for node, topic, cls in SOURCES:
            self.bus.subscribe(node, topic, cls, self._queue)
        self._writer = self.spawn(self._write_loop, "writer")

    def _queue(self, msg: Any) -> None:
        # between prints the 100 Hz states need no writer (a job's first state opens it)
        if self.recorder is None and (isinstance(msg, ExtruderState) or (
                isinstance(msg, RobotState) and not msg.job_id)):
            return
        try:
            self.inbox.put_nowait(msg)
        except queue.Full:  # the writer is far behind: drop rather than block the bus
            pass

    def _write_loop(self) -> None:
        while not self.stopping.is_set():
            try:
                msg = self.inbox.get(timeout=0.2)
            except queue.Empty:
                msg = None
            if msg is not None:
                self._handle(msg)
            if self.recorder is not None and time.monotonic() - self.last_seen > self.idle_s:
                self._close("idle")

    def _handle(self, msg: Any) -> None:
        if isinstance(msg, RobotState):
            if not msg.job_id:
                return  # no job on the arm
            if msg.job_id != self.job_id:
                # the moves after a job's end still name it: a new recording only for another
                # job or the same job streaming again (resumed)
                if msg.job_id == self.finished and msg.mode != RobotMode.STREAMING:
                    return
                self._close("next job")
                self._open(msg.job_id, msg.t)
            self.last_seen = time.monotonic()
        if self.recorder is None:
            return
        if getattr(msg, "job_id", self.job_id) not in (self.job_id, ""):
            return
        self.recorder.record(msg)
        if (isinstance(msg, StreamEvent) and msg.job_id == self.job_id
                and msg.kind in (StreamEnd.DONE, StreamEnd.STOPPED)):
            self.finished = self.job_id
            self._close(msg.kind)

    def _open(self, job_id: str, t: float) -> None:
        from planner.trajectory import Trajectory

        try:
            job_dir = Path(self.store.get(job_id).dir)
            traj = Trajectory.load(job_dir)
        except Exception as exc:  # a job the store or disk cannot give: no recording
            log.warning("no telemetry for job %s: %s", job_id, exc)
            self.job_id = job_id
            return
        path = job_dir / "telemetry.mcap"
        n = 2
        while path.exists():
            path, n = job_dir / f"telemetry-{n}.mcap", n + 1
        self.recorder = JobRecorder(path, traj.tcp, self.record_hz, self.max_mb)
        self.recorder.record_plan(traj.t, traj.q, traj.tcp, traj.extrude, t)
        self.job_id = job_id
        log.info("recording job %s to %s", job_id, path)

    def _close(self, why: str) -> None:
        if self.recorder is not None:
            self.recorder.close()
            log.info("closed %s (%s): %s", self.recorder.path, why, self.recorder.counts)
        self.recorder = None
        self.job_id = ""

    def on_shutdown(self) -> None:
        # the writer thread stops with ``stopping``; what is still queued is written after it
        writer = getattr(self, "_writer", None)
        if writer is not None:
            writer.join(5.0)
        while True:
            try:
                self._handle(self.inbox.get_nowait())
            except queue.Empty:
                break
        self._close("shutdown")
        self.store.close()


def main(argv: Sequence[str] | None = None) -> int:
    """Process entry point."""
    return node_main(RecorderNode, argv, "recorder")


if __name__ == "__main__":
    raise SystemExit(main())
