"""Following a stream the supervisor asked the robot for: checkpoints, progress, its end.

``StreamFollow._stream`` asks the robot node to stream a range of servo samples and
``_monitor`` follows it until its end event (or, if that event was lost on the bus, the end
the robot's state and status show): it records the last waypoint the robot passed as the
job's checkpoint and publishes the job's progress and ETA. The job's extruded volume is the
controller's totaliser times the profile's true-per-nominal ratio (``_volume``).
"""

from __future__ import annotations

import logging
import queue
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from mesp_cell.drivers.stream import StreamPlan
from mesp_cell.jobs import JobRecord
from mesp_cell.messages import Command, JobProgress, StreamEvent, WaypointReached
from mesp_cell.nodes import print_ledger
from mesp_cell.nodes.cell_steps import CellSteps, Stopped
from mesp_cell.nodes.eta_estimate import EtaEstimate
from mesp_cell.states import RobotMode, StreamEnd

log = logging.getLogger("mesp.supervisor")


class StreamFollow(CellSteps):
    """A stream of one job and what the supervisor records while it runs."""

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
        since = time.time()
        reply = self._request(self.names["robot"], Command.make("stream", job.id, **args))
        if not reply.ok:
            raise Stopped(reply.reason)
        if started is not None:
            started()
        return self._monitor(job, plan, ext0, since)

    def _checkpoint(self, job: JobRecord, plan: StreamPlan) -> tuple[int, int]:
        """(waypoint, sample) the robot's ledger last printed (-1, -1: nothing yet), recorded
        as the job's checkpoint."""
        waypoint, sample = print_ledger.read(Path(job.dir)).last
        if waypoint >= 0:
            i = int(np.searchsorted(plan.wp_id, waypoint))
            self.store.checkpoint(job.id, int(plan.wp_layer[i]), waypoint, sample)
        return waypoint, sample

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
                or rs.mode not in (RobotMode.IDLE, RobotMode.STOPPED)):
            return None
        reply = self._request(self.names["robot"], Command.make("status"), 1.0)
        if not reply.ok or reply.value("mode") not in (RobotMode.IDLE, RobotMode.STOPPED):
            return None
        log.warning("the end of the stream of %s did not arrive; the robot is %s", job_id,
                    reply.value("mode"))
        why = str(reply.value("stop_reason", ""))
        kind = StreamEnd.DONE if reply.value("mode") == RobotMode.IDLE else StreamEnd.STOPPED
        return StreamEvent(job_id, kind, why, rs.sample, float(reply.value("stop_t", time.time())))

    def _monitor(self, job: JobRecord, plan: StreamPlan, ext0: float,
                 since: float = 0.0) -> StreamEvent:
        """Follow the stream (checkpoints, progress) until it ends (an end event stamped at
        or after ``since``, the stream request's time: not a stale one). The robot node
        switches the extruder on the servo clock."""
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
                if (ev.job_id == job.id and ev.kind in (StreamEnd.DONE, StreamEnd.STOPPED)
                        and ev.t >= since):
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

