"""The supervisor: the ETA from the pace the stream keeps; the tank-ready gate and the abort's
retract over the real processes (synthetic slicing and planning, the kinematic twin)."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from mesp_cell.cell_client import CellClient
from mesp_cell.jobs import JobRecord
from mesp_cell.launcher import Launch
from mesp_cell.messages import RobotState
from mesp_cell.nodes.eta_estimate import EtaEstimate
from planner.cell import load_cell
from tests.mesp_cell.conftest import Console

pytestmark = pytest.mark.slow  # nodes on the bus


def test_eta_follows_the_measured_pace_not_the_asked_one() -> None:
    # asked: 80x at 2 ms = 40,000 samples/s; kept: 32,000 (a lagging twin)
    eta = EtaEstimate(40_000.0)
    assert eta(0.0, 0, 1_000_000) == pytest.approx(25.0)  # nothing measured yet: nominal
    assert eta(1.0, 32_000, 968_000) == pytest.approx(968_000 / 40_000)  # under 2 s seen
    for t in range(2, 50):
        left = eta(float(t), 32_000 * t, 2_000_000 - 32_000 * t)
    assert left == pytest.approx((2_000_000 - 32_000 * 49) / 32_000)
    # a stall: while no sample advances over the window, the nominal pace stands
    stalled = EtaEstimate(40_000.0)
    for t in range(5):
        left = stalled(float(t), 10, 1000)
    assert left == pytest.approx(1000 / 40_000)
    assert stalled(5.0, 10, -3) == 0.0


@pytest.fixture
def cell(console: Console) -> Launch:
    return console.launch


def _until(ready: Callable[[], bool], timeout: float = 10.0) -> bool:
    """Poll ``ready`` until it holds or ``timeout`` s pass (bus messages land asynchronously,
    later than the job store's record on a loaded host)."""
    end = time.monotonic() + timeout
    while not ready() and time.monotonic() < end:
        time.sleep(0.02)
    return ready()


def _wait_state(client: CellClient, job_id: str, state: str, timeout: float = 30.0) -> JobRecord:
    end = time.monotonic() + timeout
    job = client.status(job_id)
    while job.state != state and time.monotonic() < end:
        time.sleep(0.02)
        job = client.status(job_id)
    assert job.state == state, job
    return job


def test_after_an_abort_the_next_job_waits_and_nothing_moves_until_confirmed(
        cell: Launch, ring: Path) -> None:
    model = ring
    client = cell.client()
    states: list[RobotState] = []
    client.bus().subscribe("robot", "state", RobotState, states.append)
    try:
        first = client.submit(model)
        second = client.submit(model)
        _wait_state(client, first.id, "ready_check")
        # the first job of the session waits too: nothing streams or moves
        time.sleep(1.0)
        assert client.status(first.id).state == "ready_check"
        assert client.status(second.id).state == "planned"  # one job waits at a time
        assert _until(lambda: len(states) >= 50), len(states)
        assert {s.mode for s in states[-50:]} == {"idle"}
        client.confirm_ready(first.id)
        end = time.monotonic() + 30
        while client.status(first.id).percent < 30 and time.monotonic() < end:
            time.sleep(0.02)
        # paused (the nozzle stays where it stopped, in the gel), then aborted: the supervisor
        # retracts it along its axis and parks it home (a printing job's abort does the same,
        # tests/mesp_cell/web/test_api.py)
        assert client.command("pause", first.id).ok
        assert client.wait(first.id, timeout=20).state == "paused"
        reply = client.command("abort", first.id)
        assert reply.ok, reply.reason
        assert client.status(first.id).state == "aborted"
        end = time.monotonic() + 20
        while time.monotonic() < end and len(client.store.history(first.id)) < 9:
            time.sleep(0.05)
        note = client.store.history(first.id)[-1]
        assert note[1:] == ("aborted", "aborted", "nozzle retracted along its axis out of the "
                            "gel and parked at home"), note
        home = load_cell(None).robot.home_deg  # the robot node's home: the bundled cell's
        assert _until(lambda: np.abs(np.subtract(states[-1].q, home)).max() < 0.05), \
            states[-1]  # parked at home (its state may reach this test after the note)
        # the next job waits for the operator: nothing moves until the confirmation
        _wait_state(client, second.id, "ready_check")
        n = len(states)
        time.sleep(2.0)
        assert _until(lambda: len(states) - n > 50), len(states) - n  # at least 2 s of states
        assert client.status(second.id).state == "ready_check"
        still = states[n:]
        assert len(still) > 50 and {s.mode for s in still} == {"idle"}
        assert np.ptp([s.q for s in still], axis=0).max() < 1e-6
        client.confirm_ready(second.id)
        done = client.wait(second.id, timeout=30)
        assert done.state == "done", done.reason
    finally:
        client.close()


def test_ready_and_resume_are_refused_while_the_estop_is_latched(cell: Launch,
                                                                 ring: Path) -> None:
    model = ring
    client = cell.client()
    try:
        job = client.submit(model)
        _wait_state(client, job.id, "ready_check")
        client.estop("test")
        with pytest.raises(InputError, match=r"cannot ready job .*e-stop.*mesp estop --reset"):
            client.confirm_ready(job.id)
        assert client.reset_estop() == []
        client.confirm_ready(job.id)
        assert client.wait(job.id, timeout=30).state == "done"
        with pytest.raises(InputError, match="done; only a job waiting in ready_check"):
            client.confirm_ready(job.id)
    finally:
        client.close()
