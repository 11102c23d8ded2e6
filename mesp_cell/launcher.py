"""Launch descriptions (``launch/*.toml``) and the process supervisor behind ``mesp launch``.

A launch file only declares: the cell name, the bus hub, variables (``"auto"`` = a free TCP
port), and processes in start order. Each ``[[process]]`` has ``name``, ``module`` (run as
``python -m``), either ``params`` (a node: gets ``--name --bus --params``) or ``args`` (a plain
program), ``restart`` ("never" | "on-failure" | "always"), ``critical`` (a failure that is not
restarted stops everything) and ``ready`` (a line its log must show before the next process
starts; nodes are ready when their liveliness token appears) and ``heartbeat_timeout`` (s, 0 =
off; a node whose heartbeats stop that long while its process lives is hung: it is killed and
then restarted or failed like a crashed one). Strings may use ``{var}``.

``Launch`` starts the processes with one log file each, watches them, restarts or fails fast,
and stops them all in reverse order on ``stop()`` (Ctrl-C in ``mesp launch``). The launcher
holds the bus hub: every node connects to it and the peers then mesh directly. ``CellClient``
is the operator's API (submit, wait with progress, pause, resume, abort, e-stop) used by the
console commands and ``mesp demo``.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mesp_cell.bus.secret import cell_secret, private_dir, write_private
from mesp_cell.bus.session import Bus, BusConfig
from mesp_cell.drivers.extruder_emulator import free_port
from mesp_cell.job_import import submit_copies
from mesp_cell.jobs import FINAL, JobRecord, JobStore, check_submission
from mesp_cell.messages import Command, EStop, Heartbeat, JobProgress, Reply
from slicer.configtools import read_toml
from slicer.errors import InputError

RESTART = ("never", "on-failure", "always")
STARTUP_GRACE_S = 30.0  # s a node may take to send its first heartbeat


def mesp_home() -> Path:
    """The state directory: ``$MESP_HOME`` or ``~/.mesp`` (job store, job dirs, logs, run files)."""
    return Path(os.environ.get("MESP_HOME") or Path.home() / ".mesp")


def bundled_launch(name: str) -> Path:
    """A launch file shipped with the project (``launch/<name>.toml``)."""
    return Path(__file__).resolve().parent.parent / "launch" / f"{name}.toml"


@dataclass(frozen=True)
class ProcessSpec:
    """One process of a launch description (see the module docstring)."""

    name: str
    module: str
    params: Mapping[str, Any] | None = None
    args: tuple[str, ...] = ()
    restart: str = "never"
    critical: bool = True
    ready: str = ""
    max_restarts: int = 3
    heartbeat_timeout: float = 5.0

    def __post_init__(self) -> None:
        if self.restart not in RESTART:
            raise InputError(f"process '{self.name}': restart '{self.restart}' is unknown",
                             f"use one of {', '.join(RESTART)}")
        if not re.match(r"^[a-z0-9][a-z0-9_\-]*$", self.name):
            raise InputError(f"process name '{self.name}' is not a valid bus name",
                             "use lower-case letters, digits, '_' or '-'")


@dataclass(frozen=True)
class LaunchSpec:
    """A parsed launch description with its variables resolved."""

    cell: str
    hub: str
    connect: tuple[str, ...]
    processes: tuple[ProcessSpec, ...]
    vars: Mapping[str, Any] = field(default_factory=dict)


def _subst(value: Any, env: Mapping[str, Any]) -> Any:
    if isinstance(value, str):
        m = re.fullmatch(r"\{(\w+)\}", value)
        if m and m.group(1) in env:
            return env[m.group(1)]
        return re.sub(r"\{(\w+)\}", lambda g: str(env.get(g.group(1), g.group(0))), value)
    if isinstance(value, list):
        return [_subst(v, env) for v in value]
    if isinstance(value, dict):
        return {k: _subst(v, env) for k, v in value.items()}
    return value


def load_launch(path: Path, overrides: Mapping[str, Any] | None = None) -> LaunchSpec:
    """Read a launch file; ``overrides`` replace its ``[vars]``. Bad content is an InputError
    naming the key (``mesp_cell.launch_schema``), before anything starts."""
    from mesp_cell import launch_schema as check

    data = read_toml(Path(path))
    unknown = set(data) - {"cell", "bus", "vars", "process"}
    if unknown:
        raise InputError(f"{path}: unknown section [{sorted(unknown)[0]}]",
                         "allowed: [cell], [bus], [vars], [[process]]")
    env: dict[str, Any] = {"home": str(mesp_home()), "python": sys.executable}
    variables = check.table(data.get("vars", {}), f"{path}: [vars]")
    for k, v in {**variables, **(overrides or {})}.items():
        env[k] = free_port() if v == "auto" else v
    cell_table = check.table(data.get("cell", {}), f"{path}: [cell]")
    env["cell"] = cell = check.string(cell_table.get("name", "sim"), f"{path}: cell.name")
    if not re.match(r"^[a-z0-9][a-z0-9_\-]*$", cell):
        raise InputError(f"{path}: cell name '{cell}' is not a valid bus name",
                         "use lower-case letters, digits, '_' or '-'")
    bus = check.table(data.get("bus", {}), f"{path}: [bus]")
    hub = check.endpoint(bus.get("hub", "tcp/127.0.0.1:auto"), f"{path}: bus.hub", auto=True)
    if hub.endswith(":auto"):
        hub = hub[: -len("auto")] + str(free_port())
    env["hub"] = hub
    connect = check.endpoints(bus.get("connect", []), f"{path}: bus.connect")
    raw_procs = data.get("process", [])
    if not isinstance(raw_procs, list):
        raise InputError(f"{path}: process must be [[process]] tables", "see launch/sim.toml")
    procs = []
    for i, raw in enumerate(raw_procs):
        raw = check.table(raw, f"{path}: process #{i + 1}")
        if "name" not in raw or "module" not in raw:
            raise InputError(f"{path}: process #{i + 1} needs 'name' and 'module'",
                             "see launch/sim.toml")
        raw = _subst(raw, env)
        extra = set(raw) - {f for f in ProcessSpec.__dataclass_fields__}
        if extra:
            raise InputError(f"{path}: process '{raw['name']}' has unknown key "
                             f"'{sorted(extra)[0]}'", "see launch/sim.toml")
        where = f"{path}: process '{raw['name']}'"
        params = raw.get("params")
        procs.append(ProcessSpec(
            name=check.string(raw["name"], f"{where} name"),
            module=check.module(raw["module"], f"{where} module"),
            params=None if params is None else check.table(params, f"{where} params"),
            args=check.arguments(raw.get("args", []), f"{where} args"),
            restart=check.string(raw.get("restart", "never"), f"{where} restart"),
            critical=check.flag(raw.get("critical", True), f"{where} critical"),
            ready=check.string(raw.get("ready", ""), f"{where} ready"),
            max_restarts=int(check.number(raw.get("max_restarts", 3), f"{where} max_restarts",
                                          check.MAX_RESTARTS, whole=True)),
            heartbeat_timeout=float(check.number(raw.get("heartbeat_timeout", 5.0),
                                                 f"{where} heartbeat_timeout",
                                                 check.HEARTBEAT_TIMEOUT_S))))
    if not procs:
        raise InputError(f"{path} declares no [[process]]", "see launch/sim.toml")
    return LaunchSpec(cell, hub, connect, tuple(procs), env)


@dataclass
class _Proc:
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
    from mesp_cell.nodes.lifecycle import START_ERROR, START_FIX

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
        while job.state in ("submitted", "sliced", "planned") and time.monotonic() < end:
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
