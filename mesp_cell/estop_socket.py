"""The resident e-stop path's door: a Unix socket the e-stop node listens on.

``mesp estop`` must stop the cell within 100 ms of the command; starting zenoh and joining the
bus takes longer than that. The e-stop node (``nodes/estop_node.py``) is on the bus all the
time and listens on ``<home>/run/<cell>.estop.sock`` (mode 0600, the operator's); the command
writes one line to it (the reason, plain text), the node publishes the e-stop at once and
answers one JSON line: what stopped. ``mesp_cell.cli`` calls ``fast_estop`` before any other
import, and this module imports only what the request needs before it is sent (the C socket
module ``_socket``: the ``socket`` wrapper's enum and selectors imports took 10-20 ms on a
loaded host); ``json`` comes after, to read the answer. The command's cost is then the
interpreter's start-up and one socket write.
"""

from __future__ import annotations

import _socket
import os
import sys
from collections.abc import Sequence
from pathlib import Path


def home_dir() -> Path:
    """The state directory, as ``mesp_cell.launcher.mesp_home`` finds it."""
    return Path(os.environ.get("MESP_HOME") or Path.home() / ".mesp")


def socket_path(cell: str | None, home: Path | None = None) -> Path | None:
    """The e-stop socket of ``cell`` (None = the only running cell, else "sim"); None when
    there is none (the cell is not running, or was launched without the e-stop node)."""
    run = (home or home_dir()) / "run"
    if cell is None:
        runs = sorted(n for n in os.listdir(run) if n.endswith(".json")) if run.is_dir() else []
        cell = runs[0][: -len(".json")] if len(runs) == 1 else "sim"
    path = run / f"{cell}.estop.sock"
    return path if path.exists() else None


def request_line(reason: str) -> bytes:
    """The request: the reason on one line (newlines and NULs made spaces), UTF-8."""
    return " ".join(reason.replace("\x00", " ").split()).encode() + b"\n"


def send(path: Path, reason: str, timeout: float = 3.0) -> dict[str, object]:
    """Ask the e-stop node at ``path`` to stop the cell; returns its answer: ``sent_t`` (s since
    the epoch), ``lines`` (what stopped, when) and ``confirmed``. Raises OSError when the node
    does not answer."""
    s = _socket.socket(_socket.AF_UNIX, _socket.SOCK_STREAM)
    try:
        s.settimeout(timeout)
        s.connect(str(path))
        s.sendall(request_line(reason))
        data = b""
        while not data.endswith(b"\n"):
            chunk = s.recv(65536)
            if not chunk:
                break
            data += chunk
    finally:
        s.close()
    import json

    answer = json.loads(data.decode() or "{}")
    if not isinstance(answer, dict) or "lines" not in answer:
        raise OSError(f"the e-stop node at {path} gave no answer")
    return answer


def fast_estop(argv: Sequence[str]) -> int | None:
    """`mesp estop [--reason R] [--on CELL]` through the resident e-stop node: the exit code;
    None when it cannot (other options, no node listening): then the full command runs."""
    reason, cell = "operator", None
    rest = list(argv)
    while rest:
        opt = rest.pop(0)
        if opt in ("--reason", "--on") and rest:
            value = rest.pop(0)
            reason, cell = (value, cell) if opt == "--reason" else (reason, value)
        else:
            return None  # --reset, --help, a typo: the parser answers
    path = socket_path(cell)
    if path is None:
        return None
    try:
        answer = send(path, reason)
    except (OSError, ValueError):
        return None  # the node is gone: join the bus instead
    lines = answer.get("lines", [])
    for text in lines if isinstance(lines, list) else []:
        print(text)
    if not answer.get("confirmed"):
        print("mesp: error: the e-stop was not confirmed by every node; use the cell's "
              "hardware e-stop now", file=sys.stderr)
        return 2
    return 0
