"""Soak: print on the simulated cell over and over for a while and watch every process grow.

Starts the bundled sim cell (the MuJoCo twin, the emulated extruder, the real slicer and
planner) in a fresh MESP_HOME, submits the model, confirms the tank and waits for the end,
again and again until ``--minutes`` are up. Every ``--every`` seconds it samples each
process's resident memory, threads and open files (psutil if installed, else /proc) and at the
end reports the growth per hour of each, from a least-squares line through the samples taken
after the first job finished (imports, caches and the first job's allocations are warm-up).

    python bench/soak.py                                   # 10 minutes, examples/cube.stl
    python bench/soak.py --minutes 480 --out soak-8h.json  # the 8-hour soak
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
MAX_RESUMES = 5  # resumes of one interrupted job before it is aborted
STUCK_S = 600.0  # s without a change of the job: the soak stops and reports


@dataclass(frozen=True)
class Sample:
    """One process at one time: t (s since the start), rss (MiB), threads, files (open fds)."""

    t: float
    rss: float
    threads: int
    files: int


def sample(pid: int, t: float) -> Sample | None:
    """The process's RSS, threads and open files now, or None if it is gone."""
    try:
        import psutil
    except ImportError:
        psutil = None
    try:
        if psutil is not None:
            p = psutil.Process(pid)
            with p.oneshot():
                return Sample(t, p.memory_info().rss / 2**20, p.num_threads(), p.num_fds())
        status = Path(f"/proc/{pid}/status").read_text()
        fields = dict(line.split(":", 1) for line in status.splitlines() if ":" in line)
        rss = float(fields["VmRSS"].split()[0]) / 1024
        return Sample(t, rss, int(fields["Threads"]), len(os.listdir(f"/proc/{pid}/fd")))
    except (OSError, KeyError, ValueError):
        return None
    except Exception as exc:  # psutil.NoSuchProcess / AccessDenied
        if type(exc).__name__ in ("NoSuchProcess", "AccessDenied", "ZombieProcess"):
            return None
        raise


def per_hour(samples: list[Sample], field: str, since: float) -> float:
    """Slope of ``field`` over time, per hour, from the samples at or after ``since``."""
    pts = [(s.t, getattr(s, field)) for s in samples if s.t >= since]
    if len(pts) < 3 or pts[-1][0] - pts[0][0] < 30:
        return float("nan")
    t, v = np.array(pts, dtype=float).T
    return float(np.polyfit(t, v, 1)[0] * 3600.0)


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0, help="how long to print (10)")
    ap.add_argument("--model", type=Path, default=ROOT / "examples" / "cube.stl")
    ap.add_argument("--job", type=Path, default=ROOT / "examples" / "cube.toml")
    ap.add_argument("--time-scale", type=float, default=40.0, help="twin speed-up (40)")
    ap.add_argument("--every", type=float, default=5.0, help="s between samples (5)")
    ap.add_argument("--out", type=Path, default=None, help="write the samples as JSON here")
    args = ap.parse_args(argv)

    home = Path(tempfile.mkdtemp(prefix="mesp-soak-"))
    os.environ["MESP_HOME"] = str(home)
    from mesp_cell.launcher import start_cell

    cell = start_cell(overrides={"time_scale": args.time_scale})
    t0 = time.monotonic()
    series: dict[str, list[Sample]] = {}
    pids: dict[str, int] = {}
    stop = threading.Event()

    def sampler() -> None:
        while True:
            now = time.monotonic() - t0
            for proc in cell.procs:
                if proc.popen is None:
                    continue
                name = proc.spec.name
                if pids.get(name, proc.popen.pid) != proc.popen.pid:  # restarted: a new series
                    name = f"{name}#{proc.popen.pid}"
                pids.setdefault(proc.spec.name, proc.popen.pid)
                s = sample(proc.popen.pid, now)
                if s is not None:
                    series.setdefault(name, []).append(s)
            s = sample(os.getpid(), now)
            if s is not None:
                series.setdefault("launcher+client", []).append(s)
            if stop.wait(args.every):
                return

    thread = threading.Thread(target=sampler, daemon=True)
    thread.start()
    jobs: list[tuple[str, str, float]] = []
    ends: list[float] = []  # s since the start at which each job finished
    signal.signal(signal.SIGTERM, _interrupt)  # `kill` stops the soak with its report
    client = cell.client()
    try:
        while time.monotonic() - t0 < args.minutes * 60:
            start = time.monotonic()
            job = client.submit(args.model, args.job)
            client.confirm_ready(job.id, timeout=STUCK_S)
            end = client.wait(job.id, timeout=STUCK_S, idle=True)
            resumed = 0
            # a stop the host's load caused (a stalled servo loop): resume, as an operator would
            while end.state == "interrupted" and resumed < MAX_RESUMES:
                print(f"{time.monotonic() - t0:7.0f} s  {job.id}: interrupted ({end.reason}); "
                      "resuming", flush=True)
                client.resume(job.id)
                resumed += 1
                end = client.wait(job.id, timeout=STUCK_S, idle=True)
            if end.state in ("interrupted", "paused"):
                client.command("abort", job.id)  # frees the tank for the next job
            jobs.append((job.id, end.state, time.monotonic() - start))
            ends.append(time.monotonic() - t0)
            print(f"{time.monotonic() - t0:7.0f} s  {job.id}: {end.state} in "
                  f"{time.monotonic() - start:.0f} s", flush=True)
    except TimeoutError as exc:  # a job that stopped moving: report it and what was measured
        print(f"{time.monotonic() - t0:7.0f} s  stuck: {exc}", flush=True)
        jobs.append(("stuck", str(exc), 0.0))
    except KeyboardInterrupt:
        print(f"{time.monotonic() - t0:7.0f} s  interrupted by the user", flush=True)
    finally:
        client.close()
        stop.set()
        thread.join()
        cell.stop()
    elapsed = time.monotonic() - t0
    done = sum(1 for _, state, _ in jobs if state == "done")
    warm = 1 if len(ends) >= 3 else 0
    since = ends[warm] if ends else float("inf")
    later = len(ends) - warm - 1  # jobs after the warm-up
    print(f"\nsoak: {len(jobs)} jobs in {elapsed / 60:.1f} min ({done} done), growth from "
          f"{since:.0f} s on (after job {warm + 1}), per hour and per job:\n")
    hours = max(elapsed - since, 1e-9) / 3600
    print("| process | RSS MiB start -> end | RSS MiB/h | MiB/job | threads/h | open files/h |")
    print("| --- | --- | --- | --- | --- | --- |")
    for name, ss in sorted(series.items()):
        rate = per_hour(ss, "rss", since)
        per_job = rate * hours / later if later else float("nan")
        print(f"| {name} | {ss[0].rss:.0f} -> {ss[-1].rss:.0f} | {rate:+.1f} | {per_job:+.2f} | "
              f"{per_hour(ss, 'threads', since):+.1f} | "
              f"{per_hour(ss, 'files', since):+.1f} |")
    if args.out is not None:
        args.out.write_text(json.dumps({
            "minutes": elapsed / 60, "jobs": jobs, "ends_s": ends, "warm_up_s": since,
            "series": {k: [asdict(s) for s in v] for k, v in series.items()}}, indent=1))
    return 0 if jobs and done == len(jobs) else 1


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    raise SystemExit(main())
