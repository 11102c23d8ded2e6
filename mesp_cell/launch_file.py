"""Launch descriptions (``launch/*.toml``): the file's format and its loading.

A launch file only declares: the cell name, the bus hub, variables (``"auto"`` = a free TCP
port), and processes in start order. Each ``[[process]]`` has ``name``, ``module`` (run as
``python -m``), either ``params`` (a node: gets ``--name --bus --params``) or ``args`` (a plain
program), ``restart`` ("never" | "on-failure" | "always"), ``critical`` (a failure that is not
restarted stops everything) and ``ready`` (a line its log must show before the next process
starts; nodes are ready when their liveliness token appears) and ``heartbeat_timeout`` (s, 0 =
off; a node whose heartbeats stop that long while its process lives is hung: it is killed and
then restarted or failed like a crashed one). Strings may use ``{var}``. ``load_launch``
checks every value (``mesp_cell.launch_schema``) before anything starts.
"""

from __future__ import annotations

import re
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from core.configtools import read_toml
from core.errors import InputError
from mesp_cell import launch_schema as check
from mesp_cell.bus.secret import mesp_home
from mesp_cell.drivers.extruder_emulator import free_port

RESTART = ("never", "on-failure", "always")


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
    """``value`` with ``{var}`` replaced from ``env`` (a whole-string ``{var}`` keeps its type)."""
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
