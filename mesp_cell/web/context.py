"""What the console's API serves from (the job store, the bus, the live state), the API's
error, and a job as the API shows it."""

from __future__ import annotations

import asyncio
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from core.status import JobState
from mesp_cell.bus.session import Bus
from mesp_cell.jobs import FINAL, JobRecord, JobStore
from mesp_cell.web.live import LiveState


class ApiError(Exception):
    """An answer other than 2xx, with its one-line reason."""

    def __init__(self, status: int, detail: str) -> None:
        super().__init__(detail)
        self.status, self.detail = status, detail


@dataclass
class ConsoleContext:
    """What the API serves from. ``token`` "" = none configured; ``token_all``: every call
    needs it (the console is bound beyond loopback)."""

    cell: str
    home: Path
    db_path: Path
    bus: Bus
    live: LiveState
    token: str = ""
    token_all: bool = False
    max_upload: int = 64 << 20
    clients: set[asyncio.Queue[dict[str, Any]]] = field(default_factory=set)
    loop: asyncio.AbstractEventLoop | None = None  # the server's, once it runs
    news: asyncio.Event | None = None  # set (thread-safe) when a progress message arrives
    twin: Any = None  # the TwinView drawing the cell at the robot's pose (None: not offered)
    _local: threading.local = field(default_factory=threading.local)

    @property
    def store(self) -> JobStore:
        """This thread's connection to the job store (one SQLite connection per thread: the
        API's handlers run on a thread pool)."""
        store = getattr(self._local, "store", None)
        if store is None:
            store = self._local.store = JobStore(self.db_path)
        return store


def job_json(job: JobRecord, history: list[tuple[float, str, str, str]] | None = None
             ) -> dict[str, Any]:
    """A job as the API shows it; with its ``history``, also the duration and result."""
    out: dict[str, Any] = {
        "id": job.id, "state": job.state, "reason": job.reason, "model": Path(job.model).name,
        "created": job.created, "updated": job.updated, "layer": job.layer,
        "layers": job.layers, "waypoint": job.waypoint, "waypoints": job.waypoints,
        "percent": job.percent, "eta_s": job.eta_s if job.state == JobState.PRINTING else None,
        "ink_mm3": job.volume, "resume_pending": bool(job.resume),
        "ready_confirmed": bool(job.ready), "final": job.state in FINAL}
    if history is not None:
        starts = [t for t, _, new, _ in history if new == JobState.PRINTING]
        out["started"] = starts[0] if starts else None
        out["duration_s"] = (job.updated - starts[0]) if starts and job.state in FINAL else None
        out["result"] = job.state if job.state in FINAL else None
        out["history"] = [{"t": t, "from": a, "to": b, "reason": r} for t, a, b, r in history]
    return out


def figure_files(job_dir: Path) -> dict[str, Path]:
    """The job's PNG figures by name (the job directory and its ``figures/``)."""
    return {p.name: p for p in (*job_dir.glob("*.png"), *(job_dir / "figures").glob("*.png"))}
