"""One simulated cell with its console for the supervisor's and the console's tests over the
real processes: the real bus, synthetic slicing and a synthetic trajectory that starts and ends
at the cell's home (no long approach move), the kinematic twin at half speed so a print lasts
long enough to pause it, and a bearer token configured, so the console's motion endpoints need
it even on loopback."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from core.artifacts import save_npz
from mesp_cell.launch_file import bundled_launch
from mesp_cell.launcher import Launch, start_cell
from mesp_cell.web.node import console_urls
from mesp_cell.web.token import load_token
from planner.cell import load_cell
from tests.mesp_cell import synthetic


def plan_at_home(job_dir: Path, cell_file: Path | None) -> dict[str, Any]:
    """``synthetic.plan_job``'s trajectory moved to start at the bundled cell's home."""
    arrays = synthetic.trajectory_arrays(synthetic.LAYERS * synthetic.PER_LAYER)
    arrays["q"] = arrays["q"] - synthetic.HOME + np.radians(load_cell(None).robot.home_deg)
    save_npz(Path(job_dir) / "trajectory.npz", arrays)
    return {}


@dataclass
class Console:
    """The running cell, its console's URL and token, and an HTTP client."""

    launch: Launch
    url: str
    token: str
    home: Path
    http: httpx.Client

    @property
    def auth(self) -> dict[str, str]:
        return {"Authorization": f"Bearer {self.token}"}

    def post(self, path: str, **kw: Any) -> httpx.Response:
        return self.http.post(path, headers=self.auth, **kw)

    def job(self, job_id: str) -> dict[str, Any]:
        r = self.http.get(f"/api/jobs/{job_id}")
        assert r.status_code == 200, r.text
        return dict(r.json())

    def wait(self, job_id: str, states: tuple[str, ...], timeout: float = 30.0,
             percent: float = -1.0) -> dict[str, Any]:
        end = time.monotonic() + timeout
        job = self.job(job_id)
        while time.monotonic() < end:
            if job["state"] in states and job["percent"] >= percent:
                return job
            time.sleep(0.03)
            job = self.job(job_id)
        raise AssertionError(f"job {job_id} never reached {states}: {job}")

    def submit(self, model: Path) -> str:
        with model.open("rb") as f:
            r = self.post("/api/jobs", files={"model": (model.name, f)})
        assert r.status_code == 201, r.text
        return str(r.json()["id"])


@pytest.fixture(scope="module")
def console_cell(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Console]:
    """The cell and its console, started once per test module (see ``console``).

    Not once per session: a running cell takes about half a core while it waits (its nodes'
    state loops, heartbeats and twin), and a session's cell waited from the console's tests,
    which run early (slow files first), to the end of the run, beside the other tests."""
    home = tmp_path_factory.mktemp("console_home")
    old = os.environ.get("MESP_HOME")
    os.environ["MESP_HOME"] = str(home)
    token = load_token(home, create=True)  # configured: motion endpoints need it on loopback
    # the bundled sim launch, with a servo overrun watchdog, a Modbus deadline and a staleness
    # of the extruder's state that a loaded 2-core test host does not trip (at 150 ms the
    # deadline interrupted prints under load; the interlocks are test_safety's subject, not
    # the console's)
    try:  # the cell's processes take its home from the environment when they start
        launch = start_cell(bundled_launch("sim"), overrides={
            "servo_overrun_s": 1.0, "extruder_deadline_s": 1.0, "extruder_fresh_s": 1.0,
            "slice_fn": "tests.mesp_cell.synthetic:slice_job",
            "plan_fn": "tests.mesp_cell.conftest:plan_at_home", "prime_s": 0.1,
            "robot_backend": "twin", "time_scale": 0.5, "console_port": "auto",
            "console_max_upload_mb": 1})
    finally:  # ... and other tests of the session do not see it
        if old is None:
            os.environ.pop("MESP_HOME", None)
        else:
            os.environ["MESP_HOME"] = old
    try:
        url = console_urls(launch.spec.processes)[0]
        with httpx.Client(base_url=url, timeout=10.0) as http:
            yield Console(launch, url, token, home, http)
    finally:
        launch.stop()


@pytest.fixture
def console(console_cell: Console) -> Iterator[Console]:
    """The module's cell and console; after each test, every job it left unfinished is
    aborted and a latched e-stop cleared, so that one failed test does not hold the queue
    (one job waits at a time) for the tests after it."""
    yield console_cell
    c = console_cell
    if c.http.get("/api/cell").json()["estop"]:
        c.post("/api/estop/reset")
    for job in c.http.get("/api/jobs", params={"all": False}).json():
        c.post(f"/api/jobs/{job['id']}/abort")

@pytest.fixture
def ring(tmp_path: Path) -> Path:
    """A real mesh (the bundled cube) under another name; the synthetic slicer ignores it."""
    path = tmp_path / "ring.stl"
    path.write_bytes((Path(__file__).resolve().parents[2] / "examples" / "cube.stl").read_bytes())
    return path
