"""The job store: one SQLite file (WAL) shared by the console and the supervisor.

States: submitted -> sliced -> planned -> ready_check -> printing -> done, with paused,
interrupted (a node or link failed mid-print; resumable), failed (refused or a stage failed, with
the reason) and aborted. A fresh print never starts on its own: the supervisor parks the next
planned job in ``ready_check`` until the operator confirms the tank is ready (part removed, gel
level; ``confirm_ready``), so no job prints into the gel the last one left behind.
While printing, the supervisor writes a checkpoint (layer, waypoint, sample) of the last
waypoint deposited with the extruder confirmed running; a resume restarts from that sample, so
no waypoint is printed twice or skipped. Every transition is checked and recorded in ``events``.

A job's files are its own: ``submit`` makes the id, copies the model, job and cell files from an
import folder into the job's folder (``mesp_cell.job_import``) and records the copies. The store
and its folder are private to the user running the cell (0600 files in a 0700 folder).
"""

from __future__ import annotations

import os
import re
import shutil
import sqlite3
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, fields
from pathlib import Path

from core.errors import InputError
from core.status import JobState
from mesp_cell.bus.secret import mesp_home, private_dir
from mesp_cell.job_import import copy_into, importable, profile_refusal, safe_name

STATES = tuple(JobState)
FINAL = frozenset(s for s in JobState if s.final)
_ENDS = (JobState.FAILED, JobState.ABORTED)  # reachable from every state that is not final
TRANSITIONS: dict[str, frozenset[JobState]] = {
    JobState.SUBMITTED: frozenset({JobState.SLICED, *_ENDS}),
    JobState.SLICED: frozenset({JobState.PLANNED, *_ENDS}),
    JobState.PLANNED: frozenset({JobState.READY_CHECK, *_ENDS}),
    JobState.READY_CHECK: frozenset({JobState.PRINTING, *_ENDS}),
    JobState.PRINTING: frozenset({JobState.PAUSED, JobState.INTERRUPTED, JobState.DONE, *_ENDS}),
    JobState.PAUSED: frozenset({JobState.PRINTING, *_ENDS}),
    JobState.INTERRUPTED: frozenset({JobState.PRINTING, *_ENDS}),
    JobState.DONE: frozenset(),
    JobState.FAILED: frozenset(),
    JobState.ABORTED: frozenset(),
}

_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY, cell TEXT NOT NULL, state TEXT NOT NULL, model TEXT NOT NULL,
    job_file TEXT NOT NULL, cell_file TEXT NOT NULL, dir TEXT NOT NULL, created REAL NOT NULL,
    updated REAL NOT NULL, reason TEXT NOT NULL DEFAULT '',
    layer INTEGER NOT NULL DEFAULT -1, waypoint INTEGER NOT NULL DEFAULT -1,
    sample INTEGER NOT NULL DEFAULT -1, layers INTEGER NOT NULL DEFAULT 0,
    waypoints INTEGER NOT NULL DEFAULT 0, samples INTEGER NOT NULL DEFAULT 0,
    percent REAL NOT NULL DEFAULT 0, eta_s REAL NOT NULL DEFAULT 0,
    volume REAL NOT NULL DEFAULT 0, resume INTEGER NOT NULL DEFAULT 0,
    ready INTEGER NOT NULL DEFAULT 0
);
CREATE TABLE IF NOT EXISTS events (
    job_id TEXT NOT NULL, t REAL NOT NULL, from_state TEXT NOT NULL, to_state TEXT NOT NULL,
    reason TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS jobs_cell_state ON jobs (cell, state);
"""


@dataclass(frozen=True)
class JobRecord:
    """One job as stored.

    Attributes:
        id: job id. cell: cell name. state: one of ``STATES``. model: path of the model file.
        job_file: path of the job TOML ("" = defaults). cell_file: cell TOML ("" = bundled).
        dir: job directory (artifacts). created, updated: s since the epoch.
        reason: one line, why it failed/stopped ("" otherwise).
        layer, waypoint, sample: checkpoint, the last waypoint deposited (-1 = none).
        layers, waypoints, samples: sizes of the toolpath/trajectory (0 until planned).
        percent: 0..100 progress. eta_s: s to completion. volume: mm^3 extruded.
        resume: 1 when a resume was requested and not yet picked up.
        ready: 1 when the operator confirmed the tank for this job in ``ready_check``.
    """

    id: str
    cell: str
    state: str
    model: str
    job_file: str
    cell_file: str
    dir: str
    created: float
    updated: float
    reason: str
    layer: int
    waypoint: int
    sample: int
    layers: int
    waypoints: int
    samples: int
    percent: float
    eta_s: float
    volume: float
    resume: int
    ready: int


_COLUMNS = ", ".join(f.name for f in fields(JobRecord))


class JobStore:
    """Jobs in one SQLite file; safe for several processes (WAL, short transactions)."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        private_dir(self.path.parent)
        os.close(os.open(self.path, os.O_WRONLY | os.O_CREAT, 0o600))  # SQLite's WAL and shm
        # files take the database file's mode
        self._db = sqlite3.connect(self.path, timeout=10.0, isolation_level=None,
                                   check_same_thread=False)
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=NORMAL")
        self._db.executescript(_SCHEMA)
        cols = {r[1] for r in self._db.execute("PRAGMA table_info(jobs)")}
        if "ready" not in cols:  # a store written before the tank-ready confirmation
            self._db.execute("ALTER TABLE jobs ADD COLUMN ready INTEGER NOT NULL DEFAULT 0")

    def close(self) -> None:
        """Close the connection."""
        self._db.close()

    @contextmanager
    def _tx(self) -> Iterator[sqlite3.Connection]:
        self._db.execute("BEGIN IMMEDIATE")
        try:
            yield self._db
        except BaseException:
            self._db.execute("ROLLBACK")
            raise
        self._db.execute("COMMIT")

    # -- queries ---------------------------------------------------------------------------
    def get(self, job_id: str) -> JobRecord:
        """The job ``job_id``; an unknown id is an ``InputError``."""
        row = self._db.execute(f"SELECT {_COLUMNS} FROM jobs WHERE id = ?", (job_id,)).fetchone()
        if row is None:
            raise InputError(f"no job '{job_id}'", "list the jobs with `mesp job list`")
        return JobRecord(*row)

    def query(self, cell: str | None = None, states: tuple[str, ...] = ()) -> list[JobRecord]:
        """Jobs, oldest first, optionally of one cell and in some states."""
        sql, args = f"SELECT {_COLUMNS} FROM jobs WHERE 1=1", []
        if cell is not None:
            sql += " AND cell = ?"
            args.append(cell)
        if states:
            sql += f" AND state IN ({','.join('?' * len(states))})"
            args.extend(states)
        rows = self._db.execute(sql + " ORDER BY created, id", args).fetchall()
        return [JobRecord(*r) for r in rows]

    def next_pending(self, cell: str) -> JobRecord | None:
        """The job of ``cell`` the supervisor should work on next, or None.

        First a job that may print now (a resume requested, or the tank confirmed in
        ``ready_check``), else the oldest to slice or plan, or the oldest planned one to park
        in ``ready_check`` when no job waits there yet (one job waits for the operator at a
        time, so a confirmation always names the job that will print) and no paused or
        interrupted job holds the tank (its part is still in the gel).
        """
        row = self._db.execute(
            f"SELECT {_COLUMNS} FROM jobs WHERE cell = ? AND ((resume = 1 AND state IN "
            "('paused','interrupted')) OR (state = 'ready_check' AND ready = 1)) "
            "ORDER BY created, id LIMIT 1", (cell,),
        ).fetchone()
        if row is None:
            row = self._db.execute(
                f"SELECT {_COLUMNS} FROM jobs WHERE cell = ? AND (state IN ('submitted',"
                "'sliced') OR (state = 'planned' AND NOT EXISTS (SELECT 1 FROM jobs WHERE "
                "cell = ? AND state IN ('ready_check', 'paused', 'interrupted')))) "
                "ORDER BY created, id LIMIT 1",
                (cell, cell),
            ).fetchone()
        return JobRecord(*row) if row else None

    def history(self, job_id: str) -> list[tuple[float, str, str, str]]:
        """(t, from, to, reason) of every transition of a job, oldest first."""
        return list(self._db.execute(
            "SELECT t, from_state, to_state, reason FROM events WHERE job_id = ? ORDER BY rowid",
            (job_id,),
        ))

    # -- changes ---------------------------------------------------------------------------
    @property
    def jobs_root(self) -> Path:
        """The folder of the job folders (beside the store)."""
        return self.path.parent / "jobs"

    def submit(self, model: Path, cell: str, job_file: Path | None = None,
               cell_file: Path | None = None) -> JobRecord:
        """Record a new job in its own folder ``<jobs_root>/<id>``.

        The id is made here, never taken from a caller: the model's name reduced to
        ``[a-z0-9-]`` (at most 40 characters) and a number. The model, job and cell files must
        lie in an import folder (``job_import.importable``) and are copied into the job's
        folder; the job records the copies. Their content is checked by the caller
        (``check_submission``).
        """
        home = self.path.parent
        sources = [(importable(Path(model), home, "model"), safe_name(Path(model).name))]
        if job_file is not None:
            sources.append((importable(Path(job_file), home, "job file"), "submitted-job.toml"))
        if cell_file is not None:
            sources.append((importable(Path(cell_file), home, "cell file"), "submitted-cell.toml"))
        stem = re.sub(r"[^a-z0-9]+", "-", Path(model).stem.lower()).strip("-")[:40] or "job"
        now = time.time()
        root = private_dir(self.jobs_root)
        with self._tx() as db:
            n = db.execute("SELECT COUNT(*) FROM jobs").fetchone()[0] + 1
            job_id = f"{stem}-{n:04d}"
            while db.execute("SELECT 1 FROM jobs WHERE id = ?", (job_id,)).fetchone() \
                    or (root / job_id).exists():
                n += 1
                job_id = f"{stem}-{n:04d}"
            job_dir = root / job_id
            job_dir.mkdir(mode=0o700)
            try:
                copies = {name: str(copy_into(src, job_dir / name)) for src, name in sources}
            except OSError as exc:
                shutil.rmtree(job_dir, ignore_errors=True)
                raise InputError(f"cannot copy the job's files into {job_dir} ({exc})",
                                 "check the files and the free disk space") from exc
            db.execute(
                "INSERT INTO jobs (id, cell, state, model, job_file, cell_file, dir, created, "
                "updated) VALUES (?, ?, 'submitted', ?, ?, ?, ?, ?, ?)",
                (job_id, cell, copies[sources[0][1]], copies.get("submitted-job.toml", ""),
                 copies.get("submitted-cell.toml", ""), str(job_dir), now, now),
            )
            db.execute("INSERT INTO events VALUES (?, ?, '', 'submitted', '')", (job_id, now))
        return self.get(job_id)

    def check_transition(self, job: JobRecord, new_state: str) -> str:
        """'' if ``job`` may go to ``new_state``, else the one-line reason it may not."""
        if new_state not in STATES:
            return f"'{new_state}' is not a job state"
        if new_state in TRANSITIONS[job.state]:
            return ""
        if job.state in FINAL:
            return f"job {job.id} is {job.state}; a finished job cannot become {new_state}"
        allowed = ", ".join(sorted(TRANSITIONS[job.state]))
        return f"job {job.id} is {job.state}; it can become only {allowed}, not {new_state}"

    def transition(self, job_id: str, new_state: str, reason: str = "",
                   expect: str | None = None) -> JobRecord:
        """Move a job to ``new_state``; an invalid move raises ``InputError`` with the reason.

        ``expect`` makes the move conditional on the current state (a race is refused too).
        """
        reason = " ".join(reason.split())
        with self._tx() as db:
            row = db.execute(f"SELECT {_COLUMNS} FROM jobs WHERE id = ?", (job_id,)).fetchone()
            if row is None:
                raise InputError(f"no job '{job_id}'", "list the jobs with `mesp job list`")
            job = JobRecord(*row)
            if expect is not None and job.state != expect:
                raise InputError(f"job {job_id} is {job.state}, not {expect}", "check its status")
            why = self.check_transition(job, new_state)
            if why:
                raise InputError(why, "see `mesp job status`")
            now = time.time()
            resume = 0 if new_state == JobState.PRINTING else job.resume
            db.execute("UPDATE jobs SET state = ?, reason = ?, updated = ?, resume = ?, "
                       "ready = 0 WHERE id = ?", (new_state, reason, now, resume, job_id))
            db.execute("INSERT INTO events VALUES (?, ?, ?, ?, ?)",
                       (job_id, now, job.state, new_state, reason))
        return self.get(job_id)

    def request_resume(self, job_id: str) -> JobRecord:
        """Flag a paused or interrupted job for the supervisor to resume."""
        job = self.get(job_id)
        if job.state not in (JobState.PAUSED, JobState.INTERRUPTED):
            raise InputError(f"job {job_id} is {job.state}; only a paused or interrupted job "
                             "can be resumed", "see `mesp job status`")
        with self._tx() as db:
            db.execute("UPDATE jobs SET resume = 1, updated = ? WHERE id = ?",
                       (time.time(), job_id))
        return self.get(job_id)

    def confirm_ready(self, job_id: str, who: str = "the operator") -> JobRecord:
        """Record the operator's confirmation that the tank is ready for a job waiting in
        ``ready_check``; any other state is refused with the reason."""
        with self._tx() as db:
            row = db.execute(f"SELECT {_COLUMNS} FROM jobs WHERE id = ?", (job_id,)).fetchone()
            if row is None:
                raise InputError(f"no job '{job_id}'", "list the jobs with `mesp job list`")
            job = JobRecord(*row)
            if job.state != JobState.READY_CHECK:
                raise InputError(f"job {job_id} is {job.state}; only a job waiting in "
                                 "ready_check takes the tank-ready confirmation",
                                 "confirm it when the cell asks (`mesp job list`)")
            now = time.time()
            db.execute("UPDATE jobs SET ready = 1, updated = ? WHERE id = ?", (now, job_id))
            db.execute("INSERT INTO events VALUES (?, ?, 'ready_check', 'ready_check', ?)",
                       (job_id, now, f"tank confirmed ready by {who}"))
        return self.get(job_id)

    def unconfirm_all(self, cell: str) -> None:
        """Forget the confirmations of a previous session (the first job of a session needs
        its own)."""
        with self._tx() as db:
            db.execute("UPDATE jobs SET ready = 0 WHERE cell = ? AND state = 'ready_check'",
                       (cell,))

    def note(self, job_id: str, text: str) -> None:
        """Record ``text`` in the job's history without changing its state."""
        with self._tx() as db:
            row = db.execute("SELECT state FROM jobs WHERE id = ?", (job_id,)).fetchone()
            if row is not None:
                db.execute("INSERT INTO events VALUES (?, ?, ?, ?, ?)",
                           (job_id, time.time(), row[0], row[0], " ".join(text.split())))

    def set_sizes(self, job_id: str, layers: int, waypoints: int, samples: int) -> None:
        """Record the toolpath/trajectory sizes once planned."""
        with self._tx() as db:
            db.execute("UPDATE jobs SET layers = ?, waypoints = ?, samples = ?, updated = ? "
                       "WHERE id = ?", (layers, waypoints, samples, time.time(), job_id))

    def checkpoint(self, job_id: str, layer: int, waypoint: int, sample: int) -> None:
        """Record the last deposited waypoint; the checkpoint only moves forward."""
        with self._tx() as db:
            db.execute("UPDATE jobs SET layer = ?, waypoint = ?, sample = ?, updated = ? "
                       "WHERE id = ? AND sample <= ?",
                       (layer, waypoint, sample, time.time(), job_id, sample))

    def progress(self, job_id: str, percent: float, eta_s: float, volume: float) -> None:
        """Record live progress (percent of samples, s to go, mm^3 extruded)."""
        with self._tx() as db:
            db.execute("UPDATE jobs SET percent = ?, eta_s = ?, volume = ?, updated = ? "
                       "WHERE id = ?", (percent, eta_s, volume, time.time(), job_id))


def check_submission(model: Path, job_file: Path | None = None,
                     cell_file: Path | None = None, home: Path | None = None) -> None:
    """Refuse a job before anything is queued or moves: a one-line ``InputError`` each for a
    missing model, one the slicer cannot read (its type, or its content: the model is loaded
    and checked as ``mesp slice`` would), a symbolic link leaving its folder, a malformed job
    file, an extrusion profile outside the profile folders of ``home`` (``$MESP_HOME``), or a
    malformed cell file."""
    from slicer.config import load_job
    from slicer.mesh_io import SURFACE_SUFFIXES, TET_SUFFIXES, load_surface, load_tet_mesh

    model = Path(model)
    suffixes = SURFACE_SUFFIXES + TET_SUFFIXES
    if not model.is_file():
        raise InputError(f"model {model} does not exist", "check the path")
    if model.is_symlink():
        target = model.resolve()
        if target.parent != model.absolute().parent.resolve() or target.suffix.lower() != \
                model.suffix.lower():
            raise InputError(f"model {model} is a link to {target}, outside its folder",
                             "copy the model file itself into the folder you submit from")
    if model.suffix.lower() not in suffixes:
        raise InputError(f"model {model} has an unsupported type '{model.suffix}'",
                         f"export it as one of {', '.join(suffixes)}")
    if model.stat().st_size == 0:
        raise InputError(f"model {model} is empty", "export it again")
    job = load_job(Path(job_file) if job_file is not None else None)
    why = profile_refusal(job.extrusion.profile, home if home is not None else mesp_home())
    if why:
        raise InputError(why, "copy the profile into $MESP_HOME/profiles (`mesp profile`) and "
                         "name it there, or use 'active'")
    if model.suffix.lower() in TET_SUFFIXES:
        load_tet_mesh(model, job.model)
    else:
        load_surface(model, job.model)
    if cell_file is not None:
        from planner.cell import load_cell

        load_cell(Path(cell_file))
