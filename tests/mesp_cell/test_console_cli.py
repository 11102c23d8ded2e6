"""The operator console over a running `mesp launch` (real processes, real bus)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mesp_cell.cli import main
from tests.mesp_cell import synthetic


def mesp(*args: str) -> int:
    return main(list(args))


@pytest.fixture
def home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("MESP_HOME", str(tmp_path))
    return tmp_path


def wait_for(predicate, timeout: float = 20.0, what: object = "") -> None:  # type: ignore[no-untyped-def]
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return
        time.sleep(0.05)
    raise AssertionError(f"condition not reached {what() if callable(what) else what}")


def test_launch_submit_pause_resume_abort_and_ctrl_c(home: Path, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    model = tmp_path / "ring.stl"
    synthetic.write_cube(model)  # a real model: submit loads it
    # The launcher's stderr goes to a file: an unread pipe would block it once full.
    err_path = tmp_path / "launcher.err"
    err_file = err_path.open("wb")
    launcher = subprocess.Popen(
        [sys.executable, "-m", "mesp_cell.cli", "launch", "sim",
         "--set", "slice_fn=tests.mesp_cell.synthetic:slice_job",
         "--set", "plan_fn=tests.mesp_cell.synthetic:plan_job", "--set", "prime_s=0.1"],
        env={**os.environ, "MESP_HOME": str(home)}, stdout=subprocess.DEVNULL,
        stderr=err_file)
    try:
        run_file = home / "run" / "sim.json"
        wait_for(lambda: run_file.is_file() and (home / "run").exists())
        from mesp_cell.cell_client import CellClient

        client = CellClient.for_cell("sim")
        wait_for(lambda: "supervisor" in client.bus().alive_nodes(0.5), 30.0)
        capsys.readouterr()
        assert mesp("job", "submit", str(model)) == 0
        job_id = capsys.readouterr().out.split()[1]
        wait_for(lambda: client.status(job_id).state == "ready_check",
                 what=lambda: client.status(job_id))
        assert mesp("job", "ready", job_id) == 0
        wait_for(lambda: client.status(job_id).percent > 20, what=lambda: client.status(job_id))
        assert mesp("job", "pause", job_id) == 0
        wait_for(lambda: client.status(job_id).state == "paused")
        paused = client.status(job_id)
        assert paused.waypoint >= 0
        # A paused job cannot be paused again: a one-line reason, exit 2.
        assert mesp("job", "pause", job_id) == 2
        assert "paused" in capsys.readouterr().err
        assert mesp("job", "resume", job_id) == 0
        assert mesp("job", "status", job_id, "--follow") == 0
        assert "done" in capsys.readouterr().out
        assert client.status(job_id).state == "done"
        # Abort a queued job; list shows it only with --all.
        assert mesp("job", "submit", str(model)) == 0
        second = capsys.readouterr().out.split()[1]
        assert mesp("job", "abort", second) == 0
        wait_for(lambda: client.status(second).state == "aborted",
                 what=lambda: client.status(second))
        capsys.readouterr()
        assert mesp("job", "list") == 0
        assert second not in capsys.readouterr().out
        assert mesp("job", "list", "--all") == 0
        assert second in capsys.readouterr().out
        # e-stop from the console latches on both devices; the reset is confirmed by both.
        from mesp_cell.messages import ExtruderState

        states: list[ExtruderState] = []
        client.bus().subscribe("extruder", "state", ExtruderState, states.append)
        capsys.readouterr()
        assert mesp("estop", "--reason", "console test") == 0
        said = capsys.readouterr().out
        assert "robot: stopped and latched at" in said and "console test" in said, said
        assert "extruder: motor off, e-stop latched" in said, said
        wait_for(lambda: bool(states) and bool(states[-1].fault & 0x8))
        assert mesp("estop", "--reset") == 0
        wait_for(lambda: states[-1].fault == 0)
        pids = json.loads(run_file.read_text())["pid"]
        assert pids == launcher.pid
        client.close()
    finally:
        launcher.send_signal(signal.SIGINT)
        try:
            launcher.wait(20)
        except subprocess.TimeoutExpired:
            launcher.kill()
            pytest.fail(f"launcher did not stop on Ctrl-C; its stderr:\n{err_path.read_text()}")
        finally:
            err_file.close()
    err = err_path.read_text()
    assert "stopped supervisor" in err and "stopped extruder-emulator" in err
    assert not (home / "run" / "sim.json").exists()
    logs = list((home / "logs" / "sim").glob("*/robot.log"))
    assert logs and "robot active" in logs[0].read_text()


def test_status_line_gives_the_eta_as_hours_and_minutes(tmp_path: Path) -> None:
    from mesp_cell.commands.job import hmm, line
    from mesp_cell.jobs import JobStore

    assert (hmm(106_000), hmm(59), hmm(0), hmm(3600)) == ("29:27", "0:01", "0:00", "1:00")
    store = JobStore(tmp_path / "jobs.sqlite")
    (tmp_path / "import").mkdir()
    model = tmp_path / "import" / "part.stl"  # the store takes models from its import folder
    model.write_text("solid p\nendsolid p\n")
    job = store.submit(model, "sim")
    for state in ("sliced", "planned", "ready_check", "printing"):
        store.transition(job.id, state)
    store.set_sizes(job.id, 10, 100, 1000)
    store.progress(job.id, 12.5, 106_000.0, 3.0)
    printing = line(store.get(job.id))
    assert "ETA 29:27 (done ~" in printing and "s " not in printing.split("ETA")[1][:12]
    store.transition(job.id, "paused")
    assert "ETA" not in line(store.get(job.id))  # no "ETA 0.0 s" while paused
    store.close()
