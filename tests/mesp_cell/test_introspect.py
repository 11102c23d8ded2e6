"""`mesp node list` and `mesp topic list|echo|hz` against a running simulated cell."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from core.errors import InputError
from mesp_cell.bus.codec import encode
from mesp_cell.cli import main
from mesp_cell.introspect import message_text, rate_stats, resolve_key
from mesp_cell.messages import Heartbeat
from mesp_cell.nodes.idle_pace import IDLE_HZ


def test_keys_types_and_rates() -> None:
    assert resolve_key("sim", "robot/state") == "mesp/sim/robot/state"
    assert resolve_key("sim", "*/heartbeat") == "mesp/sim/*/heartbeat"
    assert resolve_key("sim", "mesp/lab/robot/state") == "mesp/lab/robot/state"
    with pytest.raises(InputError):
        resolve_key("sim", "state")
    with pytest.raises(InputError):
        resolve_key("sim", "Robot/state")
    name, fields = message_text(encode(Heartbeat("robot", "active", 3, 42, 1.5)))
    assert name == "Heartbeat" and fields == {"node": "robot", "state": "active", "seq": 3,
                                              "pid": 42, "t": 1.5}
    assert message_text(b"\xff\xff")[0] == "?"
    stats = rate_stats(np.arange(11) * 0.01)
    assert stats is not None and stats.hz == pytest.approx(100.0) and stats.n == 11
    assert rate_stats(np.array([1.0])) is None


def _wait(predicate, timeout: float, what: str) -> None:  # type: ignore[no-untyped-def]
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return
        time.sleep(0.1)
    raise AssertionError(what)


@pytest.fixture(scope="module")
def cell(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    home = tmp_path_factory.mktemp("home")
    old = os.environ.get("MESP_HOME")
    os.environ["MESP_HOME"] = str(home)
    err = (home / "launcher.err").open("wb")
    launcher = subprocess.Popen(
        [sys.executable, "-m", "mesp_cell.cli", "launch", "sim", "--set", "robot_backend=twin",
         "--set", "slice_fn=tests.mesp_cell.synthetic:slice_job",
         "--set", "plan_fn=tests.mesp_cell.synthetic:plan_job"],
        env={**os.environ}, stdout=subprocess.DEVNULL, stderr=err)
    try:
        from mesp_cell.cell_client import CellClient

        _wait(lambda: (home / "run" / "sim.json").is_file(), 60.0, "no run file")
        client = CellClient.for_cell("sim")
        _wait(lambda: "supervisor" in client.bus().alive_nodes(0.5), 60.0, "cell not up")
        client.close()
        yield launcher
    finally:
        launcher.send_signal(signal.SIGINT)
        try:
            launcher.wait(30)
        except subprocess.TimeoutExpired:
            launcher.kill()
        err.close()
        if old is None:
            os.environ.pop("MESP_HOME", None)
        else:
            os.environ["MESP_HOME"] = old


@pytest.mark.slow  # the cell's start
def test_node_list_shows_every_node_with_state_pid_and_heartbeat(
        cell: subprocess.Popen[bytes], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["node", "list"]) == 0
    out = capsys.readouterr().out
    for node in ("robot", "extruder", "supervisor", "planner", "slicer"):
        row = next(line for line in out.splitlines() if f" {node} " in line)
        cols = [c.strip() for c in row.strip("│ ").split("│")]
        assert cols[1] == "yes" and cols[2] == "active" and int(cols[3]) > 0
        assert 0.0 <= float(cols[4]) < 2.0  # 2 Hz heartbeat, heard within the listen window


def test_topic_list_echo_and_hz(cell: subprocess.Popen[bytes],
                                capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["topic", "list", "--listen", "1.5"]) == 0
    out = capsys.readouterr().out
    assert "mesp/sim/robot/state" in out and "RobotState" in out
    assert "mesp/sim/extruder/state" in out and "ExtruderState" in out
    assert main(["topic", "echo", "robot/state", "-n", "3"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 3
    msgs = [json.loads(line) for line in lines]
    assert all(m["type"] == "RobotState" and len(m["msg"]["q"]) == 6 for m in msgs)
    assert msgs[0]["msg"]["seq"] < msgs[2]["msg"]["seq"]
    assert main(["topic", "hz", "extruder/state", "--duration", "2.5"]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    hz = float(last.split("average rate")[1].split()[0])
    # the cell rests: published at the idle rate (``idle_pace``; 100 Hz while it moves or
    # extrudes); a loaded 2-core box delays some
    assert 0.5 * IDLE_HZ < hz < 1.3 * IDLE_HZ


def test_unknown_key_and_stopped_cell_are_one_line_errors(
        cell: subprocess.Popen[bytes], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["topic", "echo", "nobody/state", "--timeout", "0.5"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("mesp: error: no message on mesp/sim/nobody/state")
    assert main(["node", "--on", "other", "list"]) == 2
    assert "mesp launch" in capsys.readouterr().err
