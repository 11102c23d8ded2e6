"""Fault campaign: N runs per fault at a random moment of a print on the twin.

Each run prints a job (the 20 mm cube, sliced and planned once and cached), injects one fault
when the print is at a random 15-70 %, measures from the fault: the arm's stop (the robot's
servoStop time) and the screw's stop (a Modbus client polling the emulated controller's
running bit every ms), recovers (the launcher restarts a killed node; a reset after an e-stop;
a relaunch after a power loss), resumes the job and waits for its end; then reads the robot's
ledger: waypoints never printed (lost), printed twice or re-traced (doubled), and checks the
job store (``PRAGMA integrity_check``). Faults: kill -9 of each node that takes part in a
print (extruder, robot, supervisor, e-stop listener, recorder, console), the Modbus server
stopping (a disconnect) and freezing (requests unanswered), the bus going silent for the
extruder node (SIGSTOP 1 s), an e-stop by `mesp estop` (timed from the command), power loss
(SIGKILL of every process of the cell at once, then a relaunch).

    python bench/faults.py --runs 3                  # every fault, a table
    python bench/faults.py --runs 1 --faults kill-extruder,modbus-freeze
    python bench/faults.py --runs 2 --faults modbus-freeze --set extruder_deadline_s=0.07
"""

from __future__ import annotations

import argparse
import os
import random
import shutil
import signal
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

CACHE_ENV = "MESP_FAULTS_CACHE"
FAULTS = ("kill-extruder", "kill-robot", "kill-supervisor", "kill-estop", "kill-recorder",
          "kill-console", "modbus-stop", "modbus-freeze", "bus-drop", "estop", "power-loss")
#: resumes more after a resumed print was interrupted again (by the loaded host: a slow
#: Modbus exchange, a servo stall), each noted in the run
RESUMES = 2
#: faults after which the print stops and is resumed (others must not stop it)
STOPS = {"kill-extruder", "kill-robot", "kill-supervisor", "modbus-stop", "modbus-freeze",
         "bus-drop", "estop", "power-loss"}


# -- the cached job: the cell's slicer and planner replaced by copies -----------------------
def cached_slice(model: Path, job_file: Path | None, out_dir: Path, cell: str,
                 cell_file: Path | None = None) -> dict[str, Any]:
    """The slice of the cached cube (``$MESP_FAULTS_CACHE``), copied into ``out_dir``."""
    src = Path(os.environ[CACHE_ENV])
    for f in src.iterdir():
        if f.is_file() and f.name not in ("trajectory.npz", "printed.ledger"):
            shutil.copy2(f, Path(out_dir) / f.name)
    return {}


def cached_plan(job_dir: Path, cell_file: Path | None) -> dict[str, Any]:
    """The cached cube's plan, copied into ``job_dir``."""
    shutil.copy2(Path(os.environ[CACHE_ENV]) / "trajectory.npz", Path(job_dir) / "trajectory.npz")
    return {}


def prepare(cache: Path, size_mm: float) -> None:
    """Slice and plan a ``size_mm`` cube once into ``cache`` with the real pipeline."""
    if (cache / "trajectory.npz").is_file():
        return
    from mesp_cell.nodes import adapters
    from tests.mesp_cell import synthetic

    cache.mkdir(parents=True, exist_ok=True)
    model = synthetic.write_cube(cache / "cube.stl", size_mm)
    print(f"slicing and planning a {size_mm:g} mm cube into {cache} (once)", flush=True)
    adapters.slice_job(model, None, cache, "sim")
    adapters.plan_job(cache, None)


# -- measuring ---------------------------------------------------------------------------
class ScrewWatch:
    """Polls the emulated controller's running bit every ~1 ms on its own connection."""

    def __init__(self, port: int) -> None:
        from pymodbus.client import ModbusTcpClient

        self.client = ModbusTcpClient("127.0.0.1", port=port, timeout=0.05, retries=0)
        self.samples: list[tuple[float, bool]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        from mesp_cell.drivers import registers as R

        while not self._stop.is_set():
            try:
                if not self.client.connected:
                    self.client.connect()
                r = self.client.read_holding_registers(R.STATUS, count=1, device_id=1)
                if not r.isError():
                    self.samples.append((time.time(), bool(r.registers[0] & R.ST_RUNNING)))
            except Exception:  # the controller is down or frozen: no sample
                self.client.close()
            time.sleep(0.001)

    def stopped_after(self, t: float) -> float:
        """s from ``t`` to the first sample after it showing the screw off (nan if none)."""
        for ts, running in list(self.samples):
            if ts >= t and not running:
                return ts - t
        return float("nan")

    def running_at(self, t: float) -> bool:
        """The screw ran in the last sample before ``t``."""
        before = [r for ts, r in list(self.samples) if ts < t]
        return bool(before and before[-1])

    def close(self) -> None:
        self._stop.set()
        self._thread.join(1.0)
        self.client.close()


@dataclass
class Run:
    """One fault injection and its outcome."""

    fault: str
    at_percent: float = 0.0
    command_s: float = 0.0  # e-stop: s from the command's start to the e-stop on the bus
    motion_stop_s: float = float("nan")
    screw_stop_s: float = float("nan")
    stopped: bool = False
    resumed: bool = False
    state: str = ""
    reason: str = ""
    lost: int = -1
    doubled: int = -1
    volume_error: float = float("nan")
    store_ok: bool = False
    notes: list[str] = field(default_factory=list)


class Campaign:
    """The cell and the runs."""

    def __init__(self, home: Path, overrides: dict[str, Any]) -> None:
        self.home = home
        self.overrides = overrides
        self.launch: Any = None
        self.client: Any = None
        self.robot_stop_t = 0.0
        self.estop_sent = 0.0
        self.model = home / "cube.stl"
        self._old_home: str | None = None

    def start(self) -> None:
        from mesp_cell.launcher import start_cell
        from mesp_cell.messages import EStop, RobotState

        self._old_home = os.environ.get("MESP_HOME")
        os.environ["MESP_HOME"] = str(self.home)
        self.launch = start_cell(overrides=self.overrides, timeout=60.0)
        self.client = self.launch.client()

        def on_robot(m: RobotState) -> None:
            if m.stop_t > self.robot_stop_t:
                self.robot_stop_t = m.stop_t

        def on_estop(m: EStop) -> None:
            self.estop_sent = m.t

        self.client.bus().subscribe("robot", "state", RobotState, on_robot)
        self.client.bus().subscribe("estop", "estop", EStop, on_estop)

    def stop(self) -> None:
        if self.client is not None:
            self.client.close()
        if self.launch is not None:
            self.launch.stop()
        if self._old_home is None:
            os.environ.pop("MESP_HOME", None)
        else:
            os.environ["MESP_HOME"] = self._old_home

    @property
    def port(self) -> int:
        return int(self.launch.spec.vars["extruder_port"])

    def wait_percent(self, job_id: str, percent: float, timeout: float = 300.0) -> None:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            job = self.client.status(job_id)
            if job.state == "printing" and job.percent >= percent:
                return
            if job.state in ("failed", "done", "aborted", "interrupted"):
                raise RuntimeError(f"job {job_id} {job.state} before the fault: {job.reason}")
            time.sleep(0.01)
        raise RuntimeError(f"job {job_id} did not reach {percent:.0f} %")

    def run(self, fault: str, rng: random.Random) -> Run:
        from mesp_cell.nodes import print_ledger

        run = Run(fault)
        job = self.client.submit(self.model)
        self.client.confirm_ready(job.id, timeout=600.0)
        run.at_percent = rng.uniform(15.0, 70.0)
        self.wait_percent(job.id, run.at_percent)
        watch = ScrewWatch(self.port)
        time.sleep(0.1)  # samples before the fault
        try:
            t = self.inject(fault)
            time.sleep(1.5)
            if fault in ("modbus-stop", "modbus-freeze"):  # nothing reads the screw then
                run.notes.append("screw not observable while the link is down (the "
                                 "controller's watchdog stops it)")
            else:
                run.screw_stop_s = watch.stopped_after(t)
            if not watch.running_at(t):
                run.notes.append("screw was off at the fault")
        finally:
            watch.close()
        if self.robot_stop_t > t:
            run.motion_stop_s = self.robot_stop_t - t
        if fault == "estop" and self.estop_sent > t:
            run.command_s = self.estop_sent - t
        self.recover(fault)
        final = self.settled(job.id, 600.0 if fault not in STOPS else 30.0)
        if final.state == "interrupted":
            run.stopped = True
            self.resume(job.id)
            run.resumed = True
            final = self.settled(job.id, 600.0)
        for _ in range(RESUMES):  # the loaded host interrupted the resumed print again
            if final.state != "interrupted":
                break
            run.notes.append(f"re-interrupted: {final.reason}")
            self.resume(job.id)
            final = self.settled(job.id, 600.0)
        run.state, run.reason = final.state, final.reason
        job_dir = Path(self.client.store.get(job.id).dir)
        printed = print_ledger.read(job_dir)
        from mesp_cell.drivers.stream import StreamPlan

        plan = StreamPlan.load(job_dir / "trajectory.npz", 0.002)
        expected = plan.wp_id[plan.wp_extrude.astype(bool)]
        run.lost = int(printed.missing(expected).size)
        run.doubled = printed.doubled + printed.restreamed()
        from core.report import read_report

        run.volume_error = float(read_report(job_dir).get("print", {}).get("volume_error",
                                                                            float("nan")))
        db = sqlite3.connect(self.home / "jobs.sqlite")
        run.store_ok = db.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        db.close()
        return run

    def inject(self, fault: str) -> float:
        """Inject ``fault`` now; returns the time it was injected (s since the epoch)."""
        from mesp_cell.drivers import registers as R
        from mesp_cell.drivers.extruder_modbus import ModbusExtruder

        if fault.startswith("kill-"):
            pid = self.launch.pid(fault[5:])
            t = time.time()
            os.kill(pid, signal.SIGKILL)
            return t
        if fault in ("modbus-stop", "modbus-freeze"):
            kind = R.INJECT_DISCONNECT if fault == "modbus-stop" else R.INJECT_FREEZE
            injector = ModbusExtruder("127.0.0.1", self.port, retries=0)
            t = time.time()
            injector.inject(kind, 1.0)
            injector.close()
            return t
        if fault == "bus-drop":
            pid = self.launch.pid("extruder")
            t = time.time()
            os.kill(pid, signal.SIGSTOP)
            time.sleep(1.0)
            os.kill(pid, signal.SIGCONT)
            return t
        if fault == "estop":
            t = time.time()
            mesp = Path(sys.executable).with_name("mesp")
            cmd = [str(mesp)] if mesp.is_file() else [sys.executable, "-m", "mesp_cell.cli"]
            out = subprocess.run([*cmd, "estop", "--reason", "fault campaign"],
                                 capture_output=True, text=True, timeout=30)
            if out.returncode:
                raise RuntimeError(f"mesp estop failed: {out.stderr.strip()}")
            return t
        if fault == "power-loss":
            with self.launch._lock:  # no restarts: the whole cell loses power
                self.launch._stopping = True
            pids = [p.popen.pid for p in self.launch.procs
                    if p.popen is not None and p.popen.poll() is None]
            t = time.time()
            for pid in pids:
                os.kill(pid, signal.SIGKILL)
            return t
        raise ValueError(f"unknown fault '{fault}'")

    def recover(self, fault: str) -> None:
        if fault.startswith("kill-"):
            if not self.launch.wait_alive(fault[5:], 60.0):
                raise RuntimeError(f"{fault[5:]} was not restarted")
            # the killed process's presence may be withdrawn after its successor's appeared
            # (zenoh liveliness), which nodes then take for the successor leaving
            time.sleep(2.0)
        elif fault == "estop":
            bad = self.client.reset_estop()
            if bad:
                raise RuntimeError(f"{bad} did not confirm the reset")
        elif fault == "power-loss":
            self.stop()
            self.start()
        time.sleep(0.5)

    def clear(self) -> None:
        """Abort the jobs a failed run left in the tank (they hold the queue)."""
        for job in self.client.store.query(self.client.cell, ("interrupted", "paused")):
            self.client.command("abort", job.id)
        time.sleep(2.0)

    def settled(self, job_id: str, timeout: float) -> Any:
        """The job once it is no longer printing (or waiting to), or after ``timeout``."""
        end = time.monotonic() + timeout
        while True:
            job = self.client.status(job_id)
            if job.state not in ("printing", "ready_check", "planned") or (
                    time.monotonic() > end):
                return job
            time.sleep(0.05)

    def resume(self, job_id: str) -> None:
        end = time.monotonic() + 60.0
        while True:
            try:
                self.client.resume(job_id)
                return
            except Exception:
                if time.monotonic() > end:
                    raise
                time.sleep(0.5)


def campaign(faults: list[str], runs: int, time_scale: float, backend: str, seed: int,
             cache: Path, size_mm: float,
             on_run: Callable[[Run], None] = lambda r: None,
             launch_vars: dict[str, str] | None = None) -> list[Run]:
    """Run every fault ``runs`` times on one cell (a power loss relaunches it)."""
    prepare(cache, size_mm)
    os.environ[CACHE_ENV] = str(cache)
    rng = random.Random(seed)
    home = Path(tempfile.mkdtemp(prefix="mesp_faults_"))
    from tests.mesp_cell import synthetic

    c = Campaign(home, {"slice_fn": "bench.faults:cached_slice",
                        "plan_fn": "bench.faults:cached_plan", "time_scale": time_scale,
                        "robot_backend": backend, "prime_s": 0.5, **(launch_vars or {})})
    synthetic.write_cube(c.model, size_mm)
    c.start()
    out: list[Run] = []
    try:
        for _ in range(runs):
            for fault in faults:
                try:
                    r = c.run(fault, rng)
                except RuntimeError as exc:  # the run could not be made (counted as such)
                    r = Run(fault, state="not run", reason=str(exc))
                if r.state != "done":
                    c.clear()
                on_run(r)
                out.append(r)
    finally:
        c.stop()
        shutil.rmtree(home, ignore_errors=True)
    return out


def _ms(values: list[float]) -> str:
    v = [x * 1000 for x in values if x == x]
    if not v:
        return "-"
    return f"{statistics.median(v):.0f} / {max(v):.0f}"


def table(runs: list[Run]) -> str:
    """The campaign's table, one row per fault (markdown)."""
    rows = ["| fault | runs | arm stop ms (median / max) | screw stop ms (median / max) | "
            "resumed | done | lost | doubled | store ok |",
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    # an e-stop's times are from the command; its start-up is also shown on its own
    for fault in dict.fromkeys(r.fault for r in runs):
        rs = [r for r in runs if r.fault == fault and r.state != "not run"]
        if not rs:
            continue
        stops = fault in STOPS  # the others must not stop the print: no stop times
        arm = _ms([r.motion_stop_s for r in rs]) if stops else "prints on"
        screw = _ms([r.screw_stop_s for r in rs]) if stops else "prints on"
        if fault in ("modbus-stop", "modbus-freeze"):
            screw = "link down: watchdog"
        rows.append(
            f"| {fault} | {len(rs)} | {arm} | {screw} | {sum(r.resumed for r in rs)} | "
            f"{sum(r.state == 'done' for r in rs)} | {sum(max(r.lost, 0) for r in rs)} | "
            f"{sum(max(r.doubled, 0) for r in rs)} | {sum(r.store_ok for r in rs)}/{len(rs)} |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=3, help="runs per fault")
    ap.add_argument("--faults", default=",".join(FAULTS), help="comma-separated subset")
    ap.add_argument("--time-scale", type=float, default=40.0, help="the twin's speed-up")
    ap.add_argument("--backend", default="mujoco", help="mujoco | twin (kinematic)")
    ap.add_argument("--size-mm", type=float, default=20.0, help="the cube's edge")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "mesp_faults_cube")
    ap.add_argument("--set", action="append", default=[], metavar="VAR=VALUE",
                    help="a launch variable of launch/sim.toml, e.g. extruder_deadline_s=0.07")
    args = ap.parse_args(argv)
    launch_vars = dict(kv.split("=", 1) for kv in args.set if "=" in kv)
    faults = [f for f in args.faults.split(",") if f]
    unknown = set(faults) - set(FAULTS)
    if unknown:
        ap.error(f"unknown faults {sorted(unknown)}; choose from {', '.join(FAULTS)}")

    def show(r: Run) -> None:
        print(f"{r.fault:16s} at {r.at_percent:4.0f} %: arm {r.motion_stop_s * 1000:6.1f} ms, "
              f"(command start-up {r.command_s * 1000:.0f} ms) "
              f"screw {r.screw_stop_s * 1000:6.1f} ms, resumed {r.resumed}, {r.state} "
              f"{r.reason[:60]!r}, lost {r.lost}, doubled {r.doubled}, volume "
              f"{100 * r.volume_error:+.2f} %, store ok {r.store_ok} {' '.join(r.notes)}",
              flush=True)

    runs = campaign(faults, args.runs, args.time_scale, args.backend, args.seed, args.cache,
                    args.size_mm, show, launch_vars)
    print(table(runs))
    skipped = [r for r in runs if r.state == "not run"]
    if skipped:
        print(f"{len(skipped)} runs could not be made: " + "; ".join(
            f"{r.fault}: {r.reason}" for r in skipped))
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the test cube (tests/)
    raise SystemExit(main())
