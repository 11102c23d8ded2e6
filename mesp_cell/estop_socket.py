"""The resident e-stop path's door: a Unix socket the e-stop node listens on.

``mesp estop`` must stop the cell within 100 ms of the command; starting zenoh and joining the
bus takes longer than that. The e-stop node (``nodes/estop_node.py``) is on the bus all the
time and listens on ``<home>/run/<cell>.estop.sock`` (mode 0600, the operator's); the command
writes one line to it, the node publishes the e-stop at once and answers what stopped. This
module only uses the standard library, so the command starts in tens of milliseconds.
"""

from __future__ import annotations

import json
import os
import socket
from pathlib import Path


def home_dir() -> Path:
    """The state directory, as ``mesp_cell.launcher.mesp_home`` finds it."""
    return Path(os.environ.get("MESP_HOME") or Path.home() / ".mesp")


def socket_path(cell: str | None, home: Path | None = None) -> Path | None:
    """The e-stop socket of ``cell`` (None = the only running cell, else "sim"); None when
    there is none (the cell is not running, or was launched without the e-stop node)."""
    run = (home or home_dir()) / "run"
    if cell is None:
        runs = sorted(run.glob("*.json")) if run.is_dir() else []
        cell = runs[0].stem if len(runs) == 1 else "sim"
    path = run / f"{cell}.estop.sock"
    return path if path.exists() else None


def send(path: Path, reason: str, timeout: float = 3.0) -> dict[str, object]:
    """Ask the e-stop node at ``path`` to stop the cell; returns its answer: ``sent_t`` (s since
    the epoch), ``lines`` (what stopped, when) and ``confirmed``. Raises OSError when the node
    does not answer."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(timeout)
        s.connect(str(path))
        s.sendall(json.dumps({"reason": reason}).encode() + b"\n")
        data = b""
        while not data.endswith(b"\n"):
            chunk = s.recv(65536)
            if not chunk:
                break
            data += chunk
    answer = json.loads(data.decode() or "{}")
    if not isinstance(answer, dict) or "lines" not in answer:
        raise OSError(f"the e-stop node at {path} gave no answer")
    return answer
