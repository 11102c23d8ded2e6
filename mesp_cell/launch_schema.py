"""The checks of a launch file's values (``launch/*.toml``), each an ``InputError`` naming the
key, what it must be and the fix: types, finite numbers in range, bus endpoints with a valid
port. ``mesp_cell.launch_file.load_launch`` applies them before anything starts."""

from __future__ import annotations

import math
import re
import typing
from typing import Any

from core.errors import InputError

#: heartbeat_timeout range (s): 0 = off, else up to an hour.
HEARTBEAT_TIMEOUT_S = (0.0, 3600.0)
#: max_restarts range.
MAX_RESTARTS = (0, 100)
_ENDPOINT = re.compile(r"^(tcp|udp)/(?P<host>\[[0-9a-fA-F:]+\]|[A-Za-z0-9.\-]+):(?P<port>\w+)$")
_MODULE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")
FIX = "see launch/sim.toml for the format"


def string(value: Any, where: str) -> str:
    """``value`` if it is a string."""
    if not isinstance(value, str):
        raise InputError(f"{where} must be a string, got {value!r}", f"quote it; {FIX}")
    return value


def table(value: Any, where: str) -> dict[str, Any]:
    """``value`` if it is a table."""
    if not isinstance(value, dict):
        raise InputError(f"{where} must be a table, got {value!r}", FIX)
    return value


def endpoint(value: Any, where: str, auto: bool = False) -> str:
    """A bus endpoint ``tcp/HOST:PORT`` (``PORT`` 1-65535, or ``auto`` where allowed)."""
    text = string(value, where)
    found = _ENDPOINT.match(text)
    port = found["port"] if found else ""
    ok = found is not None and ((auto and port == "auto") or
                                (port.isdigit() and 1 <= int(port) <= 65535))
    if not ok:
        raise InputError(f"{where} '{text}' is not a bus endpoint",
                         "write tcp/HOST:PORT with a port from 1 to 65535"
                         + (" or auto" if auto else ""))
    return text


def endpoints(value: Any, where: str) -> tuple[str, ...]:
    """A list of bus endpoints."""
    if not isinstance(value, list):
        raise InputError(f"{where} must be a list of endpoints, got {value!r}",
                         "write connect = [\"tcp/HOST:PORT\"]")
    return tuple(endpoint(v, f"{where}[{i}]") for i, v in enumerate(value))


def module(value: Any, where: str) -> str:
    """A dotted Python module name."""
    text = string(value, where)
    if not _MODULE.match(text):
        raise InputError(f"{where} '{text}' is not a module name", "write e.g. "
                         "mesp_cell.nodes.robot_node")
    return text


def number(value: Any, where: str, bounds: tuple[float, float], whole: bool = False) -> float:
    """A finite number (whole if ``whole``) within ``bounds``."""
    kinds: tuple[type, ...] = (int,) if whole else (int, float)
    if isinstance(value, bool) or not isinstance(value, kinds):
        raise InputError(f"{where} must be a {'whole ' if whole else ''}number, got {value!r}",
                         f"write a number from {bounds[0]:g} to {bounds[1]:g}")
    x = float(typing.cast(float, value))
    if not (math.isfinite(x) and bounds[0] <= x <= bounds[1]):
        raise InputError(f"{where} = {value!r} is outside {bounds[0]:g} to {bounds[1]:g}",
                         f"write a number from {bounds[0]:g} to {bounds[1]:g}")
    return x


def flag(value: Any, where: str) -> bool:
    """true or false."""
    if not isinstance(value, bool):
        raise InputError(f"{where} must be true or false, got {value!r}", "write true or false")
    return value


def arguments(value: Any, where: str) -> tuple[str, ...]:
    """A list of program arguments (strings or numbers)."""
    if not isinstance(value, list) or not all(
            isinstance(v, str | int | float) and not isinstance(v, bool) for v in value):
        raise InputError(f"{where} must be a list of strings or numbers, got {value!r}",
                         "write args = [\"--flag\", \"value\"]")
    return tuple(str(v) for v in value)
