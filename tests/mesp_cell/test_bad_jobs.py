"""Over real processes: a bad job fails fast with its reason and the cell goes on to the next.

The cell runs the synthetic slicer (``synthetic.slice_by_name``) and planner, so a job takes
seconds; the bad jobs are a garbage .vtu that reached the queue (the supervisor reads it
first and fails it), a model on which the slicing library calls ``sys.exit`` (the slicer node
refuses it and lives on) and one that kills the slicer's worker thread (the node says so,
stops, the job fails at once and the launcher restarts the node). A valid job then prints.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from mesp_cell.cell_client import CellClient
from mesp_cell.launcher import Launch
from tests.mesp_cell import synthetic

pytestmark = pytest.mark.slow  # a cell and bad jobs through it

FAST_S = 30.0  # a failing job fails within this (the old wait was 3600 s)


@pytest.fixture(scope="module")
def cell(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Launch]:
    with synthetic.cell_in_home(tmp_path_factory.mktemp("mesp_home"),
                                slice_fn="tests.mesp_cell.synthetic:slice_by_name",
                                robot_backend="twin") as launch:
        yield launch


@pytest.fixture(scope="module")
def client(cell: Launch) -> Iterator[CellClient]:
    c = cell.client()
    yield c
    c.close()


def _fails_fast(client: CellClient, job_id: str) -> str:
    start = time.monotonic()
    job = client.wait(job_id, timeout=120)
    assert job.state == "failed", f"{job.state}: {job.reason}"
    assert time.monotonic() - start < FAST_S, f"failed only after {time.monotonic() - start} s"
    return job.reason


def test_bad_jobs_fail_fast_and_a_good_one_prints(cell: Launch, client: CellClient,
                                                  tmp_path: Path) -> None:
    # A garbage .vtu in the queue (put there through the API, past `mesp job submit`'s check).
    (client.home / "import").mkdir(exist_ok=True)
    garbage = client.home / "import" / "garbage.vtu"
    garbage.write_bytes(b"<?xml \x00\xff garbage" * 5)
    job = client.store.submit(garbage, client.cell)
    assert "not a readable tet mesh" in _fails_fast(client, job.id)

    # The slicing library calls sys.exit: the node refuses the job and keeps serving.
    slicer_pid = cell.pid("slicer")
    job = client.submit(synthetic.write_cube(tmp_path / "exits.stl"))
    assert "library gave up" in _fails_fast(client, job.id)
    assert cell.pid("slicer") == slicer_pid

    # The worker thread dies: the node reports it and stops, the launcher restarts it.
    job = client.submit(synthetic.write_cube(tmp_path / "kills.stl"))
    assert "slicer node stopped" in _fails_fast(client, job.id)
    end = time.monotonic() + 60
    while cell.pid("slicer") == slicer_pid and time.monotonic() < end:
        time.sleep(0.1)
    assert cell.pid("slicer") != slicer_pid, "the launcher did not restart the slicer"
    assert cell.wait_alive("slicer", 60)

    # The cell goes on: a valid job prints to the end.
    job = client.submit(synthetic.write_cube(tmp_path / "part.stl"))
    client.confirm_ready(job.id, timeout=120)  # the operator confirms the tank
    done = client.wait(job.id, timeout=120)
    assert done.state == "done", done.reason
