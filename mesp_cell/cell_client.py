"""``CellClient``: the operator's API to one cell (submit, wait with progress, pause, resume,
abort, e-stop), used by the console commands and ``mesp demo``. It reads the job store
directly and sends commands over the bus to the cell ``mesp launch`` runs (its run file).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from core.errors import InputError
from core.status import JobState
from mesp_cell.bus.secret import cell_secret, mesp_home
from mesp_cell.bus.session import Bus, BusConfig
from mesp_cell.job_import import submit_copies
from mesp_cell.jobs import FINAL, JobRecord, JobStore, check_submission
from mesp_cell.messages import Command, EStop, JobProgress, Reply


def _pid_alive(pid: int) -> bool:
    """The process exists (a run file left by a killed launcher names a dead one)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class CellClient:
    """The operator's view of one cell: the job store plus commands over the bus."""

    def __init__(self, cell: str, bus_config: BusConfig | None = None,
                 home: Path | None = None) -> None:
        self.cell = cell
        self.home = Path(home) if home else mesp_home()
        self.store = JobStore(self.home / "jobs.sqlite")
        self._bus_config = bus_config
        self._bus: Bus | None = None

    @staticmethod
    def for_cell(cell: str | None = None, home: Path | None = None) -> CellClient:
        """A client from the run file ``mesp launch`` wrote (bus endpoint), or store-only."""
        home = Path(home) if home else mesp_home()
        run_dir = home / "run"
        if cell is None:
            runs = sorted(run_dir.glob("*.json")) if run_dir.is_dir() else []
            cell = runs[0].stem if len(runs) == 1 else "sim"
        cfg = None
        run = run_dir / f"{cell}.json"
        data = json.loads(run.read_text()) if run.is_file() else None
        if data is not None and _pid_alive(int(data.get("pid", 0))):
            cfg = BusConfig(cell=cell, listen=("tcp/127.0.0.1:0",),
                            connect=(data["hub"], *data.get("connect", [])))
        return CellClient(cell, cfg, home)

    @property
    def running(self) -> bool:
        """A run file names this cell's bus (``mesp launch`` is, or was, running it)."""
        return self._bus_config is not None

    def bus(self) -> Bus:
        """The bus session (opened on first use); an InputError if the cell is not running."""
        if self._bus is None:
            if self._bus_config is None:
                raise InputError(f"cell '{self.cell}' is not running",
                                 "start it with `mesp launch launch/sim.toml`")
            secret = cell_secret(self.cell, self.home)  # the key of this client's home
            try:
                self._bus = Bus(self._bus_config, f"console-{os.getpid()}", secret=secret)
            except Exception as exc:  # zenoh: the hub's address cannot be reached
                raise InputError(f"cannot reach cell '{self.cell}' on the bus ({exc})",
                                 "check that `mesp launch` is running for this cell") from exc
            time.sleep(0.3)  # let the peers mesh before the first query
        return self._bus

    def close(self) -> None:
        """Close the bus session and the store."""
        if self._bus is not None:
            self._bus.close()
            self._bus = None
        self.store.close()

    # -- jobs ------------------------------------------------------------------------------
    def submit(self, model: Path, job_file: Path | None = None,
               cell_file: Path | None = None) -> JobRecord:
        """Check the inputs (one-line InputError if bad) and queue a job for this cell."""
        check_submission(model, job_file, cell_file, self.home)
        return submit_copies(self.store, self.cell, self.home, model, job_file, cell_file)

    def status(self, job_id: str) -> JobRecord:
        return self.store.get(job_id)

    def wait(self, job_id: str, on_progress: Callable[[JobRecord], None] | None = None,
             timeout: float = 3600.0, poll_s: float = 0.2,
             until: frozenset[str] = FINAL | {"paused", "interrupted"},
             idle: bool = False) -> JobRecord:
        """Wait until the job reaches a state in ``until``, reporting progress as it goes.

        A paused or interrupted job whose resume is pending does not count as stopped.
        ``timeout`` counts from the call, or with ``idle`` from the job's last change (a new
        state or checkpoint), so a long print that advances is followed to its end.

        Raises:
            TimeoutError: ``timeout`` s passed (without a change, with ``idle``).
        """
        end = time.monotonic() + timeout
        job = self.store.get(job_id)
        while job.state not in until or job.resume:
            if time.monotonic() > end:
                how = "without progress" if idle else "in all"
                raise TimeoutError(f"job {job_id} still {job.state} after {timeout:g} s {how}")
            if on_progress is not None:
                on_progress(job)
            time.sleep(poll_s)
            seen = job.updated
            job = self.store.get(job_id)
            if idle and job.updated != seen:
                end = time.monotonic() + timeout
        if on_progress is not None:
            on_progress(job)
        return job

    def resume(self, job_id: str, timeout: float = 10.0) -> JobRecord:
        """Ask the supervisor to resume a job and wait until it picks the job up."""
        reply = self.command("resume", job_id)
        if not reply.ok:
            raise InputError(reply.reason, "see `mesp job status`")
        end = time.monotonic() + timeout
        job = self.store.get(job_id)
        while job.resume and time.monotonic() < end:
            time.sleep(0.02)
            job = self.store.get(job_id)
        return job

    def command(self, verb: str, job_id: str, **args: Any) -> Reply:
        """pause | resume | abort | ready (tank confirmed) a job through the supervisor."""
        self.store.get(job_id)  # an unknown id is an InputError before touching the bus
        return self.bus().request("supervisor", Command.make(verb, job_id, **args), 5.0)

    def confirm_ready(self, job_id: str, timeout: float = 30.0,
                      who: str = "the operator") -> JobRecord:
        """Wait until the job waits in ``ready_check`` (it slices and plans first), then
        confirm the tank is ready. A refusal (e-stop latched, job ended) is an InputError."""
        end = time.monotonic() + timeout
        job = self.store.get(job_id)
        before = (JobState.SUBMITTED, JobState.SLICED, JobState.PLANNED)
        while job.state in before and time.monotonic() < end:
            time.sleep(0.05)
            job = self.store.get(job_id)
        reply = self.command("ready", job_id, who=who)
        if not reply.ok:
            raise InputError(reply.reason, "see `mesp job status`")
        return self.store.get(job_id)

    def estop(self, reason: str = "operator") -> float:
        """Publish an e-stop to every node of the cell; returns when it was sent (s)."""
        t = time.time()
        self.bus().publish_to("estop", "estop", EStop(f"console-{os.getpid()}", reason, t))
        return t

    def reset_estop(self) -> list[str]:
        """Clear latched e-stops; returns the nodes that did not confirm."""
        bad = []
        for node, verb in (("robot", "reset"), ("extruder", "reset")):
            if not self.bus().request(node, Command.make(verb), 3.0).ok:
                bad.append(node)
        return bad

    def follow(self, callback: Callable[[JobProgress], None]) -> None:
        """Call ``callback`` with every progress message of the supervisor."""
        self.bus().subscribe("supervisor", "progress", JobProgress, callback)
