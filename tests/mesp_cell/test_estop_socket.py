"""The e-stop door: `mesp estop`'s request to the resident node, and its answer."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from mesp_cell.estop_socket import fast_estop, request_line, socket_path


def fake_node(path: Path, confirmed: bool, got: list[bytes]) -> threading.Thread:
    """A node that takes one request and answers it."""
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(str(path))
    server.listen(1)

    def serve() -> None:
        conn, _ = server.accept()
        with conn:
            got.append(conn.recv(4096))
            conn.sendall(json.dumps({"sent_t": time.time(), "lines": ["robot stopped"],
                                     "confirmed": confirmed}).encode() + b"\n")
        server.close()

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    return t


def test_the_request_is_one_line_of_plain_text() -> None:
    assert request_line("fault\ncampaign\x00 now") == b"fault campaign now\n"


@pytest.mark.parametrize("confirmed", [True, False])
def test_fast_estop_asks_the_node_and_reports_its_answer(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        confirmed: bool) -> None:
    monkeypatch.setenv("MESP_HOME", str(tmp_path))
    (tmp_path / "run").mkdir()
    assert socket_path("sim") is None and fast_estop(["--on", "sim"]) is None  # no node
    (tmp_path / "run" / "sim.json").write_text("{}")
    got: list[bytes] = []
    t = fake_node(tmp_path / "run" / "sim.estop.sock", confirmed, got)
    assert fast_estop(["--reason", "test"]) == (0 if confirmed else 2)
    t.join(5)
    assert got == [b"test\n"]
    out = capsys.readouterr()
    assert "robot stopped" in out.out
    assert ("hardware e-stop" in out.err) is not confirmed
    assert fast_estop(["--reset"]) is None  # the full command answers other options


def test_mesp_estop_imports_nothing_heavy_before_the_request(tmp_path: Path) -> None:
    got: list[bytes] = []
    (tmp_path / "run").mkdir()
    t = fake_node(tmp_path / "run" / "sim.estop.sock", True, got)
    code = ("import sys; sys.argv = ['mesp', 'estop', '--on', 'sim']\n"
            "import mesp_cell.cli\n")
    out = subprocess.run([sys.executable, "-X", "importtime", "-c", code], capture_output=True,
                         text=True, env={"MESP_HOME": str(tmp_path), "PATH": "/usr/bin",
                                         "PYTHONPATH": ":".join(sys.path)}, timeout=60)
    t.join(5)
    assert out.returncode == 0, out.stderr
    assert got == [b"operator\n"]
    imported = {line.split("|")[-1].strip() for line in out.stderr.splitlines()
                if line.startswith("import time:")}
    assert "mesp_cell.estop_socket" in imported
    for heavy in ("argparse", "numpy", "zenoh", "core.errors", "mesp_cell.commands"):
        assert heavy not in imported, heavy
