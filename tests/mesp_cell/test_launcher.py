"""Launch descriptions: parsing, variables, refusals; restart policy on a tiny launch."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest

from core.errors import InputError
from mesp_cell.launch_file import bundled_launch, load_launch
from mesp_cell.launcher import Launch, LaunchFailed


def test_bundled_launch_files_parse(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("MESP_HOME", str(tmp_path))
    sim = load_launch(bundled_launch("sim"))
    assert [p.name for p in sim.processes] == [
        "extruder-emulator", "extruder", "robot", "estop", "slicer", "planner", "recorder",
        "supervisor", "console"]
    port = sim.vars["extruder_port"]
    assert isinstance(port, int) and port > 0
    ext = next(p for p in sim.processes if p.name == "extruder")
    assert ext.params is not None and ext.params["port"] == port  # typed substitution
    emu = sim.processes[0]
    assert emu.args[:2] == ("--port", str(port))
    sup = sim.processes[-2]
    assert sup.params is not None and sup.params["jobs_db"] == f"{tmp_path}/jobs.sqlite"
    for spec in (sim, load_launch(bundled_launch("cell"))):  # both serve the web console
        con = spec.processes[-1]
        assert con.module == "mesp_cell.web.node" and con.params is not None
        assert con.params["host"] == "127.0.0.1" and not con.critical
        assert con.params["jobs_db"] == f"{tmp_path}/jobs.sqlite"
    assert sim.hub.startswith("tcp/127.0.0.1:") and not sim.hub.endswith("auto")
    cell = load_launch(bundled_launch("cell"), {"robot_host": "10.0.0.2"})
    robot = next(p for p in cell.processes if p.name == "robot")
    assert robot.params is not None and robot.params["host"] == "10.0.0.2"
    assert robot.params["backend"] == "ur5e" and robot.restart == "never"


@pytest.mark.parametrize("text, message", [
    ("[[process]]\nname = 'a'\n", "needs 'name' and 'module'"),
    ("[[process]]\nname = 'a'\nmodule = 'm'\nrestart = 'sometimes'\n", "restart"),
    ("[[process]]\nname = 'a'\nmodule = 'm'\ncolour = 1\n", "unknown key 'colour'"),
    ("[cell]\nname = 'x'\n", r"no \[\[process\]\]"),
    ("[stuff]\n", r"unknown section \[stuff\]"),
    ("[[process]]\nname = 'A B'\nmodule = 'm'\n", "not a valid bus name"),
])
def test_bad_launch_files_are_refused(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "l.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=message):
        load_launch(path)


def test_restart_policy_and_fail_fast(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MESP_HOME", str(tmp_path))
    path = tmp_path / "l.toml"
    path.write_text(
        "[cell]\nname = 'tiny'\n"
        "[[process]]\nname = 'sleeper'\nmodule = 'http.server'\nargs = ['0', '--bind', "
        "'127.0.0.1']\nrestart = 'on-failure'\nmax_restarts = 1\nready = 'Serving'\n")
    launch = Launch(load_launch(path), log_dir=tmp_path / "logs")
    launch.start(timeout=20)
    try:
        first = launch.pid("sleeper")
        os.kill(first, signal.SIGKILL)
        end = time.monotonic() + 10
        while launch.pid("sleeper") == first and time.monotonic() < end:
            launch.check()
            time.sleep(0.05)
        assert launch.pid("sleeper") != first  # restarted once
        os.kill(launch.pid("sleeper"), signal.SIGKILL)
        with pytest.raises(LaunchFailed, match="sleeper exited"):
            for _ in range(200):
                launch.check()
                time.sleep(0.05)
    finally:
        launch.stop()
    assert (tmp_path / "logs" / "sleeper.log").read_text().count("--- start") == 2
    assert not (tmp_path / "run" / "tiny.json").exists()


def test_a_stale_run_file_means_not_running(tmp_path: Path) -> None:
    import json
    import subprocess
    import sys

    from mesp_cell.cell_client import CellClient

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "sim.json").write_text(json.dumps(
        {"cell": "sim", "hub": "tcp/127.0.0.1:1", "connect": [], "pid": dead.pid}))
    client = CellClient.for_cell(home=tmp_path)
    assert client.cell == "sim" and not client.running
    with pytest.raises(InputError, match="not running"):
        client.bus()
    client.close()


def test_a_hung_node_is_killed_and_restarted(tmp_path: Path,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MESP_HOME", str(tmp_path))
    path = tmp_path / "l.toml"
    path.write_text(
        "[cell]\nname = 'hang'\n"
        "[[process]]\nname = 'slicer'\nmodule = 'mesp_cell.nodes.slicer_node'\n"
        "restart = 'on-failure'\nheartbeat_timeout = 1.5\n[process.params]\n")
    launch = Launch(load_launch(path), log_dir=tmp_path / "logs")
    launch.start(timeout=30)
    try:
        first = launch.pid("slicer")
        end = time.monotonic() + 10
        while "slicer" not in launch.beats and time.monotonic() < end:
            time.sleep(0.05)
        os.kill(first, signal.SIGSTOP)  # alive but silent: a hung process
        end = time.monotonic() + 15
        while launch.pid("slicer") == first and time.monotonic() < end:
            launch.check()
            time.sleep(0.05)
        assert launch.pid("slicer") != first
        assert launch.wait_alive("slicer")
    finally:
        launch.stop()


def test_slice_adapter_refuses_before_slicing(tmp_path: Path) -> None:
    from mesp_cell.nodes import adapters

    with pytest.raises(InputError, match="does not exist"):
        adapters.slice_job(tmp_path / "none.stl", None, tmp_path / "out", "sim")
    with pytest.raises(InputError, match="module:function"):
        adapters.resolve("no_colon")
    with pytest.raises(InputError, match="cannot load"):
        adapters.resolve("tests.mesp_cell.synthetic:missing")
    assert adapters.resolve("tests.mesp_cell.synthetic:plan_job").__name__ == "plan_job"


def test_processes_stop_when_the_launcher_dies(tmp_path: Path) -> None:
    import subprocess
    import sys

    code = (
        "import os, sys, time\n"
        "from mesp_cell.launch_file import load_launch\n"
        "from mesp_cell.launcher import Launch\n"
        "from pathlib import Path\n"
        f"p = Path({str(tmp_path)!r}) / 'l.toml'\n"
        "p.write_text(\"[cell]\\nname = 'orphan'\\n[[process]]\\nname = 'emu'\\n"
        "module = 'mesp_cell.drivers.extruder_emulator'\\nready = 'listening'\\n\")\n"
        "launch = Launch(load_launch(p), log_dir=p.parent / 'logs')\n"
        "launch.start()\n"
        "print(launch.pid('emu'), flush=True)\n"
        "os._exit(0)\n"  # the launcher dies without stopping its children
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "MESP_HOME": str(tmp_path)}, timeout=60)
    child = int(out.stdout.split()[-1])
    end = time.monotonic() + 10
    while time.monotonic() < end:
        try:
            os.kill(child, 0)
        except ProcessLookupError:
            break
        time.sleep(0.1)
    else:
        os.kill(child, signal.SIGKILL)
        raise AssertionError("the child outlived its launcher")


def test_both_launch_files_take_home_and_tool_from_the_cell(monkeypatch: pytest.MonkeyPatch,
                                                           tmp_path: Path) -> None:
    import numpy as np

    from mesp_cell.nodes.robot_node import cell_of, home_and_tool
    from planner.cell import load_cell
    from planner.reach import Reach

    monkeypatch.setenv("MESP_HOME", str(tmp_path))
    cell = load_cell()
    for name in ("sim", "cell"):
        spec = load_launch(bundled_launch(name))
        robot = next(p for p in spec.processes if p.name == "robot")
        assert robot.params is not None
        assert "home_deg" not in robot.params and "tool_T" not in robot.params
        params = dict(robot.params)
        home, tool_T = home_and_tool(params, cell_of(params))
        assert np.allclose(home, np.radians(cell.robot.home_deg))
        assert np.allclose(tool_T, cell.tool.tool_T)
    # the home is on the planner's IK branch and passes its checks
    reach = Reach(cell)
    assert reach.check(home[None]).status[0] == 0
    # a launch override still wins
    over, _ = home_and_tool({"home_deg": [0.0, -90.0, 90.0, -90.0, -90.0, 0.0]}, cell)
    assert np.allclose(np.degrees(over), [0.0, -90.0, 90.0, -90.0, -90.0, 0.0])


@pytest.mark.parametrize("params, reason, fix", [
    # nothing listens for RTDE on this port of the loopback: the controller does not answer
    ("backend = 'ur5e'\nhost = '127.0.0.1'\n", "no RTDE connection to the UR5e at 127.0.0.1",
     "ping 127.0.0.1"),
    ("backend = 'twin'\n[process.params.servo]\ngain = 5.0\n",
     "bad robot parameters: servo gain 5.0 outside", "launch file"),
])
def test_a_node_that_cannot_start_says_why_in_one_line(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, params: str, reason: str,
        fix: str) -> None:
    monkeypatch.setenv("MESP_HOME", str(tmp_path))
    path = tmp_path / "l.toml"
    path.write_text("[cell]\nname = 'lonely'\n[[process]]\nname = 'robot'\n"
                    "module = 'mesp_cell.nodes.robot_node'\n[process.params]\n" + params)
    launch = Launch(load_launch(path), log_dir=tmp_path / "logs")
    with pytest.raises(LaunchFailed, match=f"robot cannot start: {reason}") as caught:
        launch.start(timeout=30)
    assert fix in caught.value.fix and "robot.log" in caught.value.fix
    log = (tmp_path / "logs" / "robot.log").read_text()
    assert "Traceback" not in log  # the operator's mistake is one line, not a stack
