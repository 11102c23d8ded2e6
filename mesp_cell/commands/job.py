"""`mesp job ...`: submit, list, status, history, ready, pause, resume, abort print jobs."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from core.errors import InputError
from core.status import JobState
from mesp_cell.jobs import FINAL, JobRecord


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "job", help="operator commands: submit, list, status, history, ready, pause, resume, "
        "abort",
        description="Queue print jobs on a running cell and follow or control them. The job "
        "store is $MESP_HOME/jobs.sqlite (default ~/.mesp).")
    p.add_argument("--on", metavar="CELL", default=None,
                   help="name of the running cell (default: the only one running, else 'sim')")
    sub = p.add_subparsers(dest="action", metavar="ACTION")
    sub.required = True
    s = sub.add_parser("submit", help="check and queue a model for printing")
    s.add_argument("model", type=Path, help="model file (STL, OBJ, ...)")
    s.add_argument("--job", type=Path, help="job TOML (overrides slicer/defaults.toml)")
    s.add_argument("--cell", type=Path, help="cell TOML (default: the bundled cell)")
    s.add_argument("--wait", action="store_true", help="follow the job until it ends")
    s.set_defaults(func=submit)
    ls = sub.add_parser("list", help="list jobs, newest last")
    ls.add_argument("--all", action="store_true", help="include finished jobs")
    ls.set_defaults(func=list_jobs)
    st = sub.add_parser("status", help="a job's state and live progress")
    st.add_argument("job_id")
    st.add_argument("--follow", "-f", action="store_true", help="update until the job stops")
    st.set_defaults(func=status)
    h = sub.add_parser("history", help="a job's events: every state change and note, with times")
    h.add_argument("job_id")
    h.set_defaults(func=history)
    r = sub.add_parser("ready", help="confirm the tank is ready (part removed, gel level) for "
                       "the job waiting in ready_check; it then starts printing")
    r.add_argument("job_id")
    r.set_defaults(func=ready)
    ex = sub.add_parser("export", help="zip a job's report, figures, preview and telemetry")
    ex.add_argument("job_id")
    ex.add_argument("--out", type=Path, metavar="FILE.zip", help="default ./JOB_ID.zip")
    ex.set_defaults(func=export)
    for verb, text in (("pause", "pause a printing job (resumable)"),
                       ("resume", "resume a paused or interrupted job from its checkpoint"),
                       ("abort", "abort a job (not resumable)")):
        c = sub.add_parser(verb, help=text)
        c.add_argument("job_id")
        c.set_defaults(func=control, verb=verb)


def _client(args: argparse.Namespace):  # type: ignore[no-untyped-def]
    from mesp_cell.cell_client import CellClient

    return CellClient.for_cell(args.on)


def hmm(seconds: float) -> str:
    """``h:mm`` of a duration (rounded up to the minute: an ETA never promises too early)."""
    minutes = int(-(-max(seconds, 0.0) // 60))
    return f"{minutes // 60}:{minutes % 60:02d}"


def line(job: JobRecord) -> str:
    """One status line: state, layer, percent, ETA (h:mm and the finish time while printing),
    volume, reason."""
    text = f"{job.id:<20} {job.state:<11}"
    if job.samples:
        layer = f"{job.layer + 1}/{job.layers}" if job.layer >= 0 else f"-/{job.layers}"
        text += f" layer {layer:>7}  {job.percent:5.1f}%"
        if job.state == JobState.PRINTING and job.eta_s > 0:
            finish = time.strftime("%H:%M", time.localtime(time.time() + job.eta_s))
            text += f"  ETA {hmm(job.eta_s)} (done ~{finish})"
        text += f"  {job.volume:8.1f} mm^3"
    if job.reason:
        text += f"  ({job.reason})"
    return text


def profile_line(job: JobRecord) -> str:
    """The extrusion profile of the job and the one its cell prints with (``mesp profile``)."""
    from mesp_cell import profiles
    from slicer.extrusion import PROFILE_FILE, load_profile

    active = profiles.active(job.cell)
    recorded = Path(job.dir) / PROFILE_FILE
    if not recorded.is_file():
        return (f"  profile: not sliced yet; cell '{job.cell}' prints with "
                f"{profiles.describe(active)}")
    mine = load_profile(recorded)
    if mine.sha256 == active.sha256:
        return f"  profile {profiles.describe(mine)} (the cell's active profile)"
    return (f"  profile {profiles.describe(mine)}; not the cell's active profile "
            f"{active.name} ({active.sha256[:12]}): re-submit to print it")


def submit(args: argparse.Namespace) -> int:
    client = _client(args)
    try:
        job = client.submit(args.model, args.job, args.cell)
        print(f"submitted {job.id} to cell '{job.cell}' (dir {job.dir})")
        if not client.running:
            print(f"note: cell '{client.cell}' is not running; the job waits for "
                  "`mesp launch`", file=sys.stderr)
        if args.wait:
            return _follow(client, job.id)
    finally:
        client.close()
    return 0


def list_jobs(args: argparse.Namespace) -> int:
    client = _client(args)
    try:
        jobs = client.store.query(client.cell)
        if not args.all:
            jobs = [j for j in jobs if j.state not in FINAL]
        for job in jobs:
            print(line(job))
        if not jobs:
            print("no jobs" + ("" if args.all else " (use --all for finished ones)"))
    finally:
        client.close()
    return 0


def _follow(client, job_id: str) -> int:  # type: ignore[no-untyped-def]
    tty = sys.stdout.isatty()
    last = ""
    job = client.status(job_id)
    while True:
        text = line(job)
        if text != last:
            print(text + ("\x1b[K\r" if tty else "\n"), end="", flush=True)
            last = text
        if job.state in FINAL or (job.state in (JobState.PAUSED, JobState.INTERRUPTED)
                                  and not job.resume):
            break
        time.sleep(0.5)
        job = client.status(job_id)
    if tty:
        print()
    return 0 if job.state == JobState.DONE else 1


def export(args: argparse.Namespace) -> int:
    """Bundle a job's files into one zip (mesp_cell.bundle)."""
    from mesp_cell.bundle import bundle_job

    client = _client(args)
    try:
        job = client.status(args.job_id)
        out, files = bundle_job(Path(job.dir), args.out or Path(f"{job.id}.zip"))
    finally:
        client.close()
    print(f"wrote {out}: {len(files)} files, {out.stat().st_size / 1e6:.1f} MB")
    return 0


def status(args: argparse.Namespace) -> int:
    client = _client(args)
    try:
        if args.follow:
            return _follow(client, args.job_id)
        job = client.status(args.job_id)
        print(line(job))
        print(profile_line(job))
    finally:
        client.close()
    return 0


def history(args: argparse.Namespace) -> int:
    client = _client(args)
    try:
        client.status(args.job_id)
        for t, old, new, reason in client.store.history(args.job_id):
            stamp = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(t))
            change = new if old in ("", new) else f"{old} -> {new}"
            print(f"{stamp}  {change:<24}{'  ' + reason if reason else ''}")
    finally:
        client.close()
    return 0


def ready(args: argparse.Namespace) -> int:
    client = _client(args)
    try:
        job = client.status(args.job_id)
        if job.state != JobState.READY_CHECK:
            raise InputError(f"job {job.id} is {job.state}, not waiting for the tank-ready "
                             "confirmation", "confirm a job `mesp job list` shows in ready_check")
        if not client.running:
            raise InputError(f"cell '{client.cell}' is not running",
                             "start it with `mesp launch sim`")
        reply = client.command("ready", job.id, who="the operator (mesp job ready)")
        if not reply.ok:
            raise InputError(reply.reason, "see `mesp job status`")
        print(f"{job.id}: tank confirmed ready; the job starts printing")
    finally:
        client.close()
    return 0


def control(args: argparse.Namespace) -> int:
    client = _client(args)
    try:
        job = client.status(args.job_id)
        if not client.running:
            if args.verb == "abort" and not JobState(job.state).final \
                    and job.state != JobState.PRINTING:
                client.store.transition(job.id, JobState.ABORTED, "aborted by the operator")
                print(f"{job.id} aborted")
                return 0
            if args.verb == "resume":
                client.store.request_resume(job.id)
                print(f"{job.id} will resume when the cell runs")
                return 0
            raise InputError(f"cell '{client.cell}' is not running",
                             "start it with `mesp launch sim`")
        reply = client.command(args.verb, job.id)
        if not reply.ok:
            raise InputError(reply.reason, "see `mesp job status`")
        print(f"{job.id}: {args.verb} requested")
    finally:
        client.close()
    return 0
