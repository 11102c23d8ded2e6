"""The recorder node on a running simulated cell: a print's telemetry.mcap holds the states
the robot published for the job."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
import zipfile
from pathlib import Path

import pytest

from mesp_cell.cli import main
from mesp_cell.messages import RobotState
from mesp_cell.telemetry import read_counts
from tests.mesp_cell import synthetic


def _wait(predicate, timeout: float, what: str) -> None:  # type: ignore[no-untyped-def]
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            if predicate():
                return
        except Exception:  # a file still being written
            pass
        time.sleep(0.1)
    raise AssertionError(what)


def _state_times(path: Path) -> tuple[float, float]:
    """(first, last) sender time of the robot states in an MCAP file, s."""
    from mcap.reader import make_reader

    with path.open("rb") as f:
        times = [m.log_time for _s, _c, m in make_reader(f).iter_messages(
            topics=["/robot/state"])]
    return min(times) / 1e9, max(times) / 1e9


@pytest.mark.slow
def test_twin_print_records_the_published_states(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("MESP_HOME", str(tmp_path))
    model = synthetic.write_cube(tmp_path / "ring.stl")  # a real model: submit loads it
    from mesp_cell.cell_client import CellClient

    client = CellClient.for_cell("sim")  # store only until the cell runs
    err = (tmp_path / "launcher.err").open("wb")
    launcher = subprocess.Popen(
        [sys.executable, "-m", "mesp_cell.cli", "launch", "sim", "--set", "robot_backend=twin",
         "--set", "slice_fn=tests.mesp_cell.synthetic:slice_job",
         "--set", "plan_fn=tests.mesp_cell.synthetic:plan_job", "--set", "prime_s=0.1",
         "--set", "record_hz=0", "--set", "time_scale=4"],  # 4x: the moves last 1.4 s, not 5.6
        env={**os.environ}, stdout=subprocess.DEVNULL, stderr=err)
    try:
        _wait(lambda: (tmp_path / "run" / "sim.json").is_file(), 60.0, "no run file")
        client = CellClient.for_cell("sim")
        _wait(lambda: {"supervisor", "recorder"} <= client.bus().alive_nodes(0.5), 60.0,
              "cell not up")
        seen: dict[str, list[float]] = {}
        lock = threading.Lock()

        def count(state: RobotState) -> None:
            with lock:  # idle states under "", the job's under its id
                seen.setdefault(state.job_id, []).append(state.t)

        client.bus().subscribe("robot", "state", RobotState, count)
        _wait(lambda: bool(seen), 30.0, "no robot state reached the test's subscriber")
        capsys.readouterr()
        assert main(["job", "submit", str(model)]) == 0
        job_id = capsys.readouterr().out.split()[1]
        client.confirm_ready(job_id, timeout=120.0)  # the operator confirms the tank
        # on a loaded machine the robot's servo watchdog may interrupt the print, or the
        # print check fail it at the end (ink at 4x on a 10 mm^3 part): the stream ends just
        # the same, and so does the recording, which is what this test checks (the print's
        # own verdict is test_safety's and test_demo's)
        state = client.wait(job_id, timeout=120.0).state
        assert state in ("done", "interrupted", "failed"), client.status(job_id).reason
        mcap = Path(client.status(job_id).dir) / "telemetry.mcap"
        _wait(lambda: read_counts(mcap) is not None, 30.0, f"{mcap} not finished")
        counts = read_counts(mcap)
        first, last = _state_times(mcap)
        with lock:
            published = sum(first <= t <= last for t in seen[job_id])
        # from the approach to the end of the print stream, every state the robot published
        # for the job, as the bus delivered them to both subscribers
        assert published > 10
        assert abs(counts["/robot/state"] - published) <= max(2, 0.02 * published)
        assert counts["/extruder/state"] > 0 and counts["/robot/event"] >= 1  # moves, done
        assert counts["/plan/trajectory"] > 100
        if state == "done":  # the move home after the print is not a new recording
            assert not (mcap.parent / "telemetry-2.mcap").exists()
        # mesp job export bundles it with the job's report and figures
        assert main(["job", "export", job_id, "--out", str(tmp_path / "bundle.zip")]) == 0
        with zipfile.ZipFile(tmp_path / "bundle.zip") as z:
            assert "telemetry.mcap" in z.namelist()
    finally:
        client.close()
        launcher.send_signal(signal.SIGINT)
        try:
            launcher.wait(30)
        except subprocess.TimeoutExpired:
            launcher.kill()
        err.close()
