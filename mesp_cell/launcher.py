"""The process supervisor behind ``mesp launch``: ``Launch`` and ``start_cell``.

``Launch`` starts the processes of a launch description (``mesp_cell.launch_file``) with one
log file each, watches them, restarts or fails fast, and stops them all in reverse order on
``stop()`` (Ctrl-C in ``mesp launch``). The launcher holds the bus hub: every node connects to
it and the peers then mesh directly. ``Launch.client`` gives the operator's API
(``mesp_cell.cell_client.CellClient``) for the running cell.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mesp_cell.bus.secret import cell_secret, private_dir, write_private
from mesp_cell.bus.session import Bus, BusConfig
from mesp_cell.cell_client import CellClient
from mesp_cell.launch_file import LaunchSpec, ProcessSpec, bundled_launch, load_launch
from mesp_cell.messages import Heartbeat
from mesp_cell.nodes.lifecycle import START_ERROR, START_FIX

STARTUP_GRACE_S = 30.0  # s a node may take to send its first heartbeat


@dataclass
class _Proc:
    """A process of the launch and its state (the running ``popen``, log, restarts)."""

    spec: ProcessSpec
    popen: subprocess.Popen[bytes] | None = None
    log_path: Path | None = None
    restarts: int = 0
    started: float = 0.0


class LaunchFailed(RuntimeError):
    """A critical process failed and was not restarted; ``fix`` says what to do."""

    def __init__(self, message: str, fix: str = "read the process logs") -> None:
        super().__init__(message)
        self.fix = fix


def start_error(log_text: str) -> tuple[str, str]:
    """(reason, fix) from the last start-error line a node wrote to its log, or ("", "")."""
    for line in reversed(log_text.splitlines()):
        at = line.find(START_ERROR)
        if at >= 0:
            reason, _, fix = line[at + len(START_ERROR):].partition(START_FIX)
            return reason.strip(), fix.strip()
    return "", ""


class Launch:
    """The running processes of one launch description (a context manager)."""

    def __init__(self, spec: LaunchSpec, log_dir: Path | None = None,
                 on_event: Callable[[str], None] | None = None) -> None:
        self.spec = spec
        stamp = time.strftime("%Y%m%d-%H%M%S")
        self.home = Path(str(spec.vars["home"]))
        self.log_dir = Path(log_dir) if log_dir else self.home / "logs" / spec.cell / stamp
        self.procs = [_Proc(p) for p in spec.processes]
        self.on_event = on_event or (lambda text: None)
        self.bus_config = BusConfig(cell=spec.cell, listen=(spec.hub,), connect=spec.connect)
        self.node_bus_config = BusConfig(cell=spec.cell, listen=("tcp/127.0.0.1:0",),
                                         connect=(spec.hub, *spec.connect))
        self.bus: Bus | None = None
        self.alive: set[str] = set()
        self.beats: dict[str, float] = {}  # node -> monotonic time of its last heartbeat
        self.failed = ""
        self._lock = threading.Lock()
        self._stopping = False

    @property
    def run_file(self) -> Path:
        return self.home / "run" / f"{self.spec.cell}.json"

    # -- start/stop ------------------------------------------------------------------------
    def start(self, timeout: float = 30.0, monitor: bool = False) -> None:
        """Open the hub, start every process in order and wait until each is ready.

        With ``monitor``, a background thread applies the restart policies (``check``) until
        ``stop``; a critical failure is then left in ``failed``.
        """
        self.log_dir.mkdir(parents=True, exist_ok=True)
        secret = cell_secret(self.spec.cell, self.home)  # made here at the cell's first start
        try:
            self.bus = Bus(self.bus_config, "launcher", secret=secret)
        except Exception as exc:  # zenoh: the port is taken, the address is not this host's
            raise LaunchFailed(f"cannot open the bus hub {self.spec.hub} ({exc})",
                               "choose a free port in [bus] hub, or write auto") from exc
        self.bus.watch_presence(self._on_presence)
        self.bus.subscribe("*", "heartbeat", Heartbeat, self._on_heartbeat)
        private_dir(self.run_file.parent)
        write_private(self.run_file, json.dumps({
            "cell": self.spec.cell, "hub": self.spec.hub, "connect": list(self.spec.connect),
            "pid": os.getpid(), "logs": str(self.log_dir)}))
        try:
            for proc in self.procs:
                self._spawn(proc)
                self._wait_ready(proc, timeout)
        except BaseException:
            self.stop()
            raise
        if monitor:
            threading.Thread(target=self._monitor, name="launch-monitor", daemon=True).start()

    def _monitor(self) -> None:
        while not self._stopping:
            try:
                self.check()
            except LaunchFailed:
                self.stop()  # fail fast: nothing keeps running without a critical process
                return
            time.sleep(0.1)

    def _spawn(self, proc: _Proc) -> None:
        s = proc.spec
        cmd = [sys.executable, "-m", s.module]
        if s.params is not None:
            cmd += ["--name", s.name, "--bus", self.node_bus_config.to_json(),
                    "--params", json.dumps(dict(s.params))]
        cmd += list(s.args)
        proc.log_path = self.log_dir / f"{s.name}.log"
        # The children import this checkout whatever their working directory.
        root = str(Path(__file__).resolve().parent.parent)
        path = os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH", "")) if p)
        env = {**os.environ, "PYTHONUNBUFFERED": "1", "MESP_HOME": str(self.home),
               "PYTHONPATH": path, "MESP_LAUNCHER_PID": str(os.getpid())}
        with open(proc.log_path, "ab") as log:
            log.write(f"--- start {time.strftime('%H:%M:%S')}: {' '.join(cmd)}\n".encode())
            log.flush()
            proc.popen = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env,
                                          stdin=subprocess.DEVNULL, start_new_session=True)
        proc.started = time.monotonic()
        self.on_event(f"started {s.name} (pid {proc.popen.pid})")

    def _wait_ready(self, proc: _Proc, timeout: float) -> None:
        s = proc.spec
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            assert proc.popen is not None
            if proc.popen.poll() is not None:
                reason, fix = start_error(self._log_text(proc))
                if reason:
                    raise LaunchFailed(f"{s.name} cannot start: {reason}",
                                       f"{fix} (log: {proc.log_path})" if fix
                                       else f"read its log: {proc.log_path}")
                raise LaunchFailed(f"{s.name} exited with code {proc.popen.returncode} while "
                                   f"starting", f"read its log: {proc.log_path}")
            if s.params is not None and s.name in self.alive:
                return
            if s.params is None and (not s.ready or s.ready in self._log_text(proc)):
                return
            time.sleep(0.02)
        raise LaunchFailed(f"{s.name} was not ready within {timeout:g} s",
                           f"read its log: {proc.log_path}")

    @staticmethod
    def _log_text(proc: _Proc) -> str:
        try:
            return proc.log_path.read_text(errors="replace") if proc.log_path else ""
        except OSError:
            return ""

    def _on_presence(self, node: str, alive: bool) -> None:
        (self.alive.add if alive else self.alive.discard)(node)

    def _on_heartbeat(self, beat: Heartbeat) -> None:
        self.beats[beat.node] = time.monotonic()

    def stop(self, grace_s: float = 3.0) -> None:
        """Stop every process: SIGTERM to all (last started first), then SIGKILL to those still
        running ``grace_s`` later. One shared deadline, so the whole stop takes at most about
        ``grace_s`` + 2 s however many processes there are."""
        with self._lock:
            self._stopping = True
        running = [proc for proc in reversed(self.procs)
                   if proc.popen is not None and proc.popen.poll() is None]
        for proc in running:
            assert proc.popen is not None
            proc.popen.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + grace_s
        for proc in running:
            assert proc.popen is not None
            try:
                proc.popen.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.popen.kill()
                proc.popen.wait(2.0)
            self.on_event(f"stopped {proc.spec.name}")
        if self.bus is not None:
            self.bus.close()
            self.bus = None
        try:
            if self.run_file.is_file() and json.loads(self.run_file.read_text()).get(
                    "pid") == os.getpid():
                self.run_file.unlink()
        except (OSError, ValueError):
            pass

    def __enter__(self) -> Launch:
        if self.bus is None:
            self.start(monitor=True)
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- monitoring ------------------------------------------------------------------------
    def wait_alive(self, name: str, timeout: float = 20.0) -> bool:
        """Wait until node ``name`` holds its liveliness token (e.g. after a restart)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if name in self.alive:
                return True
            time.sleep(0.02)
        return False

    def pid(self, name: str) -> int:
        """OS pid of the process ``name`` (for tests and diagnostics)."""
        for proc in self.procs:
            if proc.spec.name == name and proc.popen is not None:
                return proc.popen.pid
        raise KeyError(name)

    def check(self) -> None:
        """One monitoring pass: restart or fail per policy. Raises ``LaunchFailed``."""
        with self._lock:
            if self._stopping:
                return
            now = time.monotonic()
            for proc in self.procs:
                p = proc.popen
                if (p is not None and p.poll() is None and proc.spec.params is not None
                        and proc.spec.heartbeat_timeout > 0):
                    beat = self.beats.get(proc.spec.name, 0.0)
                    # Before its first heartbeat a (re)started node gets a start-up grace.
                    last = beat if beat > proc.started else proc.started + STARTUP_GRACE_S
                    if now - last > proc.spec.heartbeat_timeout:
                        self.on_event(f"{proc.spec.name} sent no heartbeat for "
                                      f"{now - last:.1f} s: killing it")
                        p.kill()
                        p.wait(2.0)
                if p is None or p.poll() is None:
                    continue
                s, rc = proc.spec, p.returncode
                again = s.restart == "always" or (s.restart == "on-failure" and rc != 0)
                if again and proc.restarts < s.max_restarts:
                    proc.restarts += 1
                    self.on_event(f"{s.name} exited ({rc}); restart {proc.restarts}/"
                                  f"{s.max_restarts}")
                    self._spawn(proc)
                    continue
                proc.popen = None
                msg = f"{s.name} exited with code {rc}; see {proc.log_path}"
                self.on_event(msg)
                if s.critical:
                    self.failed = msg
                    raise LaunchFailed(msg)

    def run_forever(self, poll_s: float = 0.2) -> int:
        """Monitor until Ctrl-C (exit 0) or a critical failure (exit 1); then stop all."""
        try:
            while True:
                self.check()
                time.sleep(poll_s)
        except KeyboardInterrupt:
            return 0
        except LaunchFailed:
            return 1
        finally:
            self.stop()

    def client(self) -> CellClient:
        """A client of this cell (same job store and bus)."""
        return CellClient(self.spec.cell, self.node_bus_config, self.home)


def start_cell(launch_file: Path | None = None, overrides: Mapping[str, Any] | None = None,
               on_event: Callable[[str], None] | None = None, timeout: float = 30.0) -> Launch:
    """Start a cell (the bundled sim launch by default) and return it running.

    Use as ``with start_cell() as cell: client = cell.client(); ...``; leaving the block stops
    every process.
    """
    spec = load_launch(launch_file or bundled_launch("sim"), overrides)
    launch = Launch(spec, on_event=on_event)
    launch.start(timeout, monitor=True)
    return launch
