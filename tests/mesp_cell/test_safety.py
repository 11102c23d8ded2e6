"""Safety of the running cell: real processes on the real bus, the twin and the emulator.

One simulated cell (synthetic slicing/planning, see ``synthetic.py``) serves the whole module;
each test submits its own small job (~3 s of printing).
"""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from core.errors import InputError
from core.report import read_report
from mesp_cell.cell_client import CellClient
from mesp_cell.drivers import registers as R
from mesp_cell.drivers.extruder_modbus import ModbusExtruder
from mesp_cell.launcher import Launch
from mesp_cell.messages import FAULT_ESTOP, ExtruderState, RobotState, WaypointReached
from mesp_cell.nodes import print_ledger
from slicer.extrusion import ACTIVE, load_profile
from tests.mesp_cell import synthetic

pytestmark = pytest.mark.slow  # a cell and prints interrupted and resumed

ALL_WAYPOINTS = set(range(synthetic.LAYERS * synthetic.PER_LAYER))


class Recorder:
    """Collects waypoint events and the latest robot/extruder states from the bus."""

    def __init__(self, client: CellClient) -> None:
        self.lock = threading.Lock()
        self.waypoints: dict[str, list[int]] = {}
        self.robot: RobotState | None = None
        self.extruder: list[tuple[float, ExtruderState]] = []
        bus = client.bus()
        bus.subscribe("robot", "waypoint", WaypointReached, self._wp)
        bus.subscribe("robot", "state", RobotState, self._robot)
        bus.subscribe("extruder", "state", ExtruderState, self._ext)

    def _wp(self, m: WaypointReached) -> None:
        with self.lock:
            self.waypoints.setdefault(m.job_id, []).append(m.waypoint)

    def _robot(self, m: RobotState) -> None:
        self.robot = m

    def _ext(self, m: ExtruderState) -> None:
        with self.lock:
            self.extruder.append((time.time(), m))
            del self.extruder[:-500]


@pytest.fixture(scope="module")
def cell(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Launch]:
    with synthetic.cell_in_home(tmp_path_factory.mktemp("mesp_home")) as launch:
        yield launch


@pytest.fixture(scope="module")
def client(cell: Launch) -> Iterator[CellClient]:
    c = cell.client()
    yield c
    c.close()


@pytest.fixture(scope="module")
def rec(client: CellClient) -> Recorder:
    return Recorder(client)


@pytest.fixture(autouse=True)
def estop_cleared(client: CellClient) -> Iterator[None]:
    """A test that fails with the e-stop latched or a job unfinished does not take the next
    tests with it."""
    yield
    synthetic.abort_unfinished(client)


@pytest.fixture
def model(tmp_path: Path) -> Path:
    path = tmp_path / "ring.stl"
    synthetic.write_cube(path)  # a real model: submit loads it
    return path


def until(ready: Callable[[], bool], timeout: float = 10.0) -> bool:
    """Poll ``ready`` until it holds or ``timeout`` s pass (bus messages land asynchronously)."""
    end = time.monotonic() + timeout
    while not ready() and time.monotonic() < end:
        time.sleep(0.01)
    return ready()


def wait_percent(client: CellClient, job_id: str, percent: float) -> None:
    end = time.monotonic() + 30
    while time.monotonic() < end:
        job = client.status(job_id)
        if job.state == "printing" and job.percent >= percent:
            return
        assert job.state in ("submitted", "sliced", "planned", "ready_check", "printing"), \
            job.reason
        time.sleep(0.02)
    raise AssertionError("the print did not progress")


def resume_and_finish(cell: Launch, client: CellClient, rec: Recorder, job_id: str,
                      node: str) -> None:
    assert cell.wait_alive(node), f"{node} was not restarted"
    picked = client.resume(job_id)
    assert picked.resume == 0, "the supervisor did not pick the job up"
    job = client.wait(job_id, timeout=30)
    assert job.state == "done", job.reason
    # The ledger is the record: a killed robot may have written a waypoint to it and died
    # before publishing its event, so the bus recorder can miss one the ledger rightly has:
    # the last one of a killed stream, and only when the robot was the process killed.
    read = print_ledger.read(Path(job.dir))
    ledger = read.waypoints.tolist()
    assert len(ledger) == len(set(ledger)), "a waypoint was printed twice"
    assert set(ledger) == ALL_WAYPOINTS, "a waypoint was skipped"
    assert ledger == sorted(ledger)
    printed = rec.waypoints[job_id]
    assert len(printed) == len(set(printed)) and printed == sorted(printed)
    killed_last = {ledger[n - 1] for n in read.stream_at[1:].tolist() if n > 0}
    unseen = set(ledger) - set(printed)
    assert unseen <= (killed_last if node == "robot" else set()), \
        f"the bus never showed waypoints {sorted(unseen)} the ledger holds"


def test_small_print_completes(client: CellClient, rec: Recorder, model: Path) -> None:
    job = client.submit(model)
    client.confirm_ready(job.id)
    done = client.wait(job.id, timeout=30)
    assert done.state == "done", done.reason
    assert sorted(rec.waypoints.get(job.id, [])) == sorted(ALL_WAYPOINTS), done
    assert done.waypoint == max(ALL_WAYPOINTS) and done.layer == synthetic.LAYERS - 1, done
    assert done.percent == 100.0, done
    # Constant rate C over ~2.4 s of deposition plus priming: the totaliser saw it.
    assert 5.0 < done.volume < 6.57 * 6, done
    history = [to for _, _, to, _ in client.store.history(job.id)]
    assert history == ["submitted", "sliced", "planned", "ready_check", "ready_check",
                       "printing", "done"], history


def test_killing_extruder_stops_robot_and_resume_completes(
        cell: Launch, client: CellClient, rec: Recorder, model: Path) -> None:
    job = client.submit(model)
    client.confirm_ready(job.id)
    wait_percent(client, job.id, 35.0)
    t_kill = time.time()
    os.kill(cell.pid("extruder"), signal.SIGKILL)
    stopped = client.wait(job.id, timeout=10)
    assert stopped.state == "interrupted"
    assert "extruder" in stopped.reason
    until(lambda: rec.robot is not None and rec.robot.stop_t > t_kill)
    assert rec.robot is not None and rec.robot.stop_t > t_kill
    latency = rec.robot.stop_t - t_kill
    print(f"robot servoStop {latency * 1000:.1f} ms after kill -9 of the extruder")
    assert latency < 0.1, f"robot stopped {latency * 1000:.0f} ms after the extruder died"
    # The checkpoint is the last waypoint the robot printed before the stop (its ledger; the
    # bus event may reach this test's recorder a little later).

    assert stopped.waypoint == print_ledger.read(Path(stopped.dir)).last[0]
    until(lambda: rec.waypoints[job.id][-1] == stopped.waypoint)
    assert stopped.waypoint == rec.waypoints[job.id][-1]
    assert 0 < stopped.waypoint < max(ALL_WAYPOINTS)
    resume_and_finish(cell, client, rec, job.id, "extruder")


def test_killing_robot_stops_extruder(cell: Launch, client: CellClient, rec: Recorder,
                                      model: Path) -> None:
    job = client.submit(model)
    client.confirm_ready(job.id)
    wait_percent(client, job.id, 35.0)
    t_kill = time.time()
    os.kill(cell.pid("robot"), signal.SIGKILL)
    stopped = client.wait(job.id, timeout=10)
    t_interrupted = time.time()
    assert stopped.state == "interrupted" and "robot" in stopped.reason

    def sent_after(t0: float) -> list[ExtruderState]:
        with rec.lock:
            return [m for _, m in rec.extruder if m.t >= t0]

    # the extruder's states sent once the job was interrupted: they may reach this test's
    # recorder a little later on a loaded host; the motor is off in every one of them
    assert until(lambda: bool(sent_after(t_interrupted))), "no extruder state after the stop"
    assert sent_after(t_kill) and not any(m.running for m in sent_after(t_interrupted)), \
        "the extruder kept running"
    resume_and_finish(cell, client, rec, job.id, "robot")


def test_estop_stops_both(cell: Launch, client: CellClient, rec: Recorder, model: Path) -> None:
    job = client.submit(model)
    client.confirm_ready(job.id)
    wait_percent(client, job.id, 30.0)
    client.estop("test")
    stopped = client.wait(job.id, timeout=10)
    assert stopped.state == "interrupted" and "e-stop" in stopped.reason
    until(lambda: bool(rec.extruder[-1][1].fault & FAULT_ESTOP))
    with rec.lock:
        last = rec.extruder[-1][1]
    assert not last.running and last.fault & FAULT_ESTOP
    assert rec.robot is not None and rec.robot.mode != "streaming"
    # A resume while the e-stop is latched is refused with the reason; nothing moves; after
    # the reset the job finishes.
    seq = rec.robot.seq
    q = rec.robot.q
    with pytest.raises(InputError, match=r"cannot resume .*e-stop.*mesp estop --reset") as err:
        client.resume(job.id)
    assert "\n" not in err.value.one_line()
    time.sleep(0.5)
    refused = client.status(job.id)
    assert refused.state == "interrupted" and not refused.resume
    assert until(lambda: rec.robot is not None and rec.robot.seq > seq)  # a newer state
    assert rec.robot.q == pytest.approx(q, abs=1e-6)
    assert client.reset_estop() == []
    resume_and_finish(cell, client, rec, job.id, "robot")


def test_modbus_disconnect_fails_safe(cell: Launch, client: CellClient, rec: Recorder,
                                      model: Path) -> None:
    job = client.submit(model)
    client.confirm_ready(job.id)
    wait_percent(client, job.id, 30.0)
    injector = ModbusExtruder("127.0.0.1", int(cell.spec.vars["extruder_port"]))
    t_inject = time.monotonic()
    injector.inject(R.INJECT_DISCONNECT, 3.0)
    injector.close()
    stopped = client.wait(job.id, timeout=10)
    assert stopped.state == "interrupted"
    assert "extruder" in stopped.reason
    # While the link is down, the node reports it after its retries, never a running motor.
    end = time.monotonic() + 2.0
    while time.monotonic() < end and rec.extruder[-1][1].connected:
        time.sleep(0.02)
    with rec.lock:
        last = rec.extruder[-1][1]
    assert not last.connected and not last.running and last.fault
    assert time.monotonic() - t_inject < 3.0, "the link fault was reported too late"
    assert until(lambda: rec.extruder[-1][1].connected, timeout=10.0), "the link did not return"
    assert cell.wait_alive("extruder")
    assert client.resume(job.id).resume == 0, "the supervisor did not pick the job up"
    end = client.wait(job.id, timeout=30)
    printed = rec.waypoints[job.id]
    assert printed == sorted(set(printed)) and set(printed) == ALL_WAYPOINTS, printed
    # The arm stopped at once (a failed exchange is a link fault), but nothing reaches a
    # disconnected controller: its own watchdog stops the screw, a blob at the stop that the
    # ink check sees. On this 9.5 mm^3 part it can exceed the 2 %; it cannot exceed the
    # watchdog's ink.
    params = next(p.params for p in cell.spec.processes if p.name == "extruder") or {}
    watchdog_ink = float(params["watchdog_ms"]) / 1000 * load_profile(ACTIVE).setpoint_mm3_s
    report = read_report(Path(client.store.get(job.id).dir))["print"]
    blob = report["part_volume_mm3"] - report["toolpath_volume_mm3"]
    print(f"after the link loss: {end.state}, {blob:+.2f} mm^3 of ink, watchdog "
          f"{watchdog_ink:.2f} mm^3")
    assert blob <= watchdog_ink + report["stop_allowance_mm3"], report
    assert end.state == "done" or (end.state == "failed" and "ink" in end.reason), end.reason


def test_bad_inputs_are_refused_before_anything_moves(
        cell: Launch, client: CellClient, rec: Recorder, model: Path, tmp_path: Path) -> None:
    bad_job = tmp_path / "job.toml"
    bad_job.write_text("[slicing]\nlayer_height_mm = 'thick'\n")
    with pytest.raises(InputError) as err:
        client.submit(model, job_file=bad_job)
    assert "\n" not in err.value.one_line() and "layer_height_mm" in err.value.one_line()
    with pytest.raises(InputError) as err:
        client.submit(tmp_path / "missing.stl")
    assert "does not exist" in err.value.one_line()
    far = tmp_path / "far_cell.toml"
    far.write_text("[tank]\nfloor_center_mm = [1400.0, 0.0, 8.0]\n[placement]\nsearch = false\n")
    samples_before = rec.robot.seq if rec.robot else 0
    job = client.submit(model, cell_file=far)
    failed = client.wait(job.id, timeout=30)
    assert failed.state == "failed"
    assert "reach" in failed.reason and "\n" not in failed.reason
    assert job.id not in rec.waypoints
    assert rec.robot is not None and rec.robot.seq > samples_before
    assert rec.robot.job_id != job.id  # no trajectory of this job was ever loaded
