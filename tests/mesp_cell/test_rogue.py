"""The bus obeys only the supervisor: every rogue action of issue 25, played from a second zenoh
session that does not hold the cell's secret (and some from one that does but may not), is
refused, and the refusal is logged by the node that refused it.

One simulated cell (synthetic slicing, a synthetic trajectory from the cell's home, so no
approach move) serves the module; the forged supervisor presence runs last (it kills the
supervisor)."""

from __future__ import annotations

import math
import os
import signal
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.artifacts import save_npz
from core.errors import InputError
from mesp_cell.bus.presence import TIMEOUT_S
from mesp_cell.bus.session import Bus, BusConfig
from mesp_cell.bus.signing import Role
from mesp_cell.jobs import JobStore
from mesp_cell.launch_file import bundled_launch
from mesp_cell.launcher import CellClient, Launch, start_cell
from mesp_cell.messages import (
    FAULT_STALL,
    Command,
    ExtruderState,
    Heartbeat,
    RobotState,
    StreamEvent,
    WaypointReached,
)
from planner.cell import load_cell
from planner.collision import CollisionModel
from tests.mesp_cell import synthetic
from tests.mesp_cell.conftest import plan_at_home

pytestmark = pytest.mark.slow  # a cell and two prints


class Watch:
    """The latest robot and extruder states as the operator sees them."""

    def __init__(self, client: CellClient) -> None:
        self.robot: RobotState | None = None
        self.extruder: list[ExtruderState] = []
        self.lock = threading.Lock()
        client.bus().subscribe("robot", "state", RobotState, self._robot)
        client.bus().subscribe("extruder", "state", ExtruderState, self._ext)

    def _robot(self, m: RobotState) -> None:
        self.robot = m

    def _ext(self, m: ExtruderState) -> None:
        with self.lock:
            self.extruder.append(m)
            del self.extruder[:-300]

    def joints(self) -> np.ndarray:
        end = time.monotonic() + 10
        while self.robot is None and time.monotonic() < end:
            time.sleep(0.02)
        assert self.robot is not None
        return np.asarray(self.robot.q)


#: a model named so gets a trajectory this many times slower (``plan_by_name``)
SLOW_MODEL, SLOW_FACTOR = "long", 4.0


def plan_by_name(job_dir: Path, cell_file: Path | None) -> dict[str, Any]:
    """``plan_at_home``; for a model named ``SLOW_MODEL*``, the same motion ``SLOW_FACTOR`` x
    slower: a print that outlasts a supervisor's restart on a loaded host."""
    out = plan_at_home(job_dir, cell_file)
    if Path(job_dir).name.startswith(SLOW_MODEL):
        path = Path(job_dir) / "trajectory.npz"
        arrays = dict(np.load(path))
        arrays["t"] = arrays["t"] * SLOW_FACTOR
        arrays["qd"] = arrays["qd"] / SLOW_FACTOR
        save_npz(path, arrays)
    return out


@pytest.fixture(scope="module")
def cell(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Launch]:
    # the kinematic twin at 0.2x: a print lasts ~9 s (a slow model's ~35 s), time for forged
    # messages to land during it; a servo overrun watchdog, a Modbus deadline and a staleness of
    # the extruder's state that a loaded 2-core host does not trip (the interlocks are
    # test_safety's subject, not the bus's)
    home = tmp_path_factory.mktemp("mesp_home")
    old = os.environ.get("MESP_HOME")
    os.environ["MESP_HOME"] = str(home)
    try:  # the cell's processes take their home from the environment when they start
        launch = start_cell(bundled_launch("sim"), overrides={
            "servo_overrun_s": 1.0, "extruder_deadline_s": 1.0, "extruder_fresh_s": 1.0,
            "slice_fn": "tests.mesp_cell.synthetic:slice_job",
            "plan_fn": "tests.mesp_cell.test_rogue:plan_by_name", "prime_s": 0.1,
            "robot_backend": "twin", "time_scale": 0.2})
    finally:
        if old is None:
            os.environ.pop("MESP_HOME", None)
        else:
            os.environ["MESP_HOME"] = old
    with launch:
        yield launch


@pytest.fixture(scope="module")
def client(cell: Launch) -> Iterator[CellClient]:
    c = cell.client()
    yield c
    c.close()


@pytest.fixture(scope="module")
def watch(client: CellClient) -> Watch:
    return Watch(client)


@pytest.fixture(autouse=True)
def jobs_ended(cell: Launch, client: CellClient) -> Iterator[None]:
    """A test whose print a loaded host's interlock interrupted does not leave that job
    holding the tank (the next test's job waited behind it in ``planned``)."""
    yield
    assert cell.wait_alive("supervisor"), "the supervisor was not restarted"
    synthetic.abort_unfinished(client)


def session(cell: Launch, name: str, secret: bytes | None, role: Role = Role.OPERATOR) -> Bus:
    """A session on the cell's bus, once it reaches the nodes it talks to."""
    bus = Bus(BusConfig(cell=cell.spec.cell, connect=(cell.spec.hub,)), name, role, secret)
    for node in ("robot", "extruder", "supervisor"):
        assert bus.wait_served(node, timeout=30.0), f"{name} never reached the {node}"
    return bus


@pytest.fixture(scope="module")
def rogue(cell: Launch) -> Iterator[Bus]:
    """A session without the cell's secret (another user on the host)."""
    bus = session(cell, "rogue", None)
    yield bus
    bus.close()


def logged(cell: Launch, node: str, text: str, timeout: float = 5.0) -> bool:
    """The node's log shows a refusal containing ``text``."""
    path = cell.log_dir / f"{node}.log"
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for line in path.read_text(errors="replace").splitlines():
            if "refused" in line and text in line:
                return True
        time.sleep(0.1)
    return False


def refused(reply_reason: str, ok: bool) -> bool:
    return not ok and "refused" in reply_reason


def rogue_trajectory(folder: Path, offset_deg: float) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    arrays = synthetic.trajectory_arrays(synthetic.LAYERS * synthetic.PER_LAYER,
                                         q_offset=math.radians(offset_deg))
    home = np.radians(load_cell(None).robot.home_deg)
    arrays["q"] = arrays["q"] - synthetic.HOME + home
    path = folder / "trajectory.npz"
    save_npz(path, arrays)
    return path


def test_rogue_trajectory_load_and_stream_are_refused(cell: Launch, rogue: Bus, watch: Watch,
                                                      tmp_path: Path) -> None:
    q0 = watch.joints()
    path = rogue_trajectory(tmp_path / "rogue", 25.0)
    r = rogue.request("robot", Command.make("load", "x", path=str(path)))
    assert refused(r.reason, r.ok), r
    r = rogue.request("robot", Command.make("stream", "x", start=0, rate=5.0))
    assert refused(r.reason, r.ok), r
    r = rogue.request("robot", Command.make("move", "x", to="sample", sample=100))
    assert refused(r.reason, r.ok), r
    assert logged(cell, "robot", "load: the sender does not hold the cell's secret")
    assert logged(cell, "robot", "stream: the sender does not hold the cell's secret")
    time.sleep(0.3)
    assert np.abs(watch.joints() - q0).max() < 0.01


def test_a_stream_far_from_the_arm_and_a_colliding_trajectory_are_refused(
        cell: Launch, client: CellClient, watch: Watch, tmp_path: Path) -> None:
    """Even from the operator (signed): the node checks start pose and clearance itself."""
    q0 = watch.joints()
    bus = client.bus()
    far = rogue_trajectory(tmp_path / "far", 25.0)
    r = bus.request("robot", Command.make("load", "far", path=str(far)), 30.0)
    assert r.ok, r.reason
    r = bus.request("robot", Command.make("stream", "far", start=0, rate=5.0))
    assert not r.ok and "25.0 deg from the arm's pose" in r.reason, r.reason
    assert logged(cell, "robot", "stream would start 25.0 deg")
    # a trajectory through the table: the shoulder swung down until the arm hits the cell
    model = CollisionModel(load_cell(None))
    home = np.radians(load_cell(None).robot.home_deg)
    swings = [home + np.radians([0, a, 0, 0, 0, 0]) for a in range(0, 181, 5)]
    clear = model.clearance(np.array(swings)).distance
    assert clear.min() < 0
    hit = int(np.argmax(clear < 0))
    arrays = synthetic.trajectory_arrays(synthetic.LAYERS * synthetic.PER_LAYER)
    M = arrays["q"].shape[0]
    s = np.linspace(0.0, 1.0, M)[:, None]
    arrays["q"] = home + s * (swings[hit] - home)
    arrays["t"] = arrays["t"] * 20  # slow enough for the joint speed limit
    arrays["qd"] = np.gradient(arrays["q"], arrays["t"], axis=0)
    (tmp_path / "hit").mkdir()
    save_npz(tmp_path / "hit" / "trajectory.npz", arrays)
    r = bus.request("robot", Command.make("load", "hit", path=str(tmp_path / "hit" /
                                                                  "trajectory.npz")), 30.0)
    assert not r.ok and "mm from the cell" in r.reason, r.reason
    assert logged(cell, "robot", "load: trajectory sample")
    assert np.abs(watch.joints() - q0).max() < 0.01


def test_estop_reset_needs_the_operator(cell: Launch, client: CellClient, rogue: Bus) -> None:
    client.estop("rogue test")
    end = time.monotonic() + 10
    while time.monotonic() < end and not client.bus().request(
            "robot", Command.make("status"), 3.0).value("estopped"):
        time.sleep(0.05)
    for node in ("robot", "extruder"):
        r = rogue.request(node, Command.make("reset"), 3.0)
        assert refused(r.reason, r.ok), r
        assert logged(cell, node, "reset: the sender does not hold the cell's secret")
    # a session holding the secret but signing as a node (the supervisor) may not either
    node_bus = session(cell, "supervisor", rogue_free_secret(cell), Role.NODE)
    try:
        for node in ("robot", "extruder"):
            r = node_bus.request(node, Command.make("reset"), 3.0)
            assert not r.ok and "accepted only from the operator" in r.reason, r
    finally:
        node_bus.close()
    status = client.bus().request("robot", Command.make("status"), 3.0)
    assert "rogue test" in str(status.value("estopped"))
    assert client.reset_estop() == []
    assert client.bus().request("robot", Command.make("status"), 3.0).value("estopped") == ""


def rogue_free_secret(cell: Launch) -> bytes:
    from mesp_cell.bus.secret import cell_secret

    key = cell_secret(cell.spec.cell, cell.home, create=False)
    assert key is not None
    return key


def test_extruder_refuses_rogue_runs_and_bad_rates(cell: Launch, client: CellClient, rogue: Bus,
                                                   watch: Watch) -> None:
    for cmd in (Command.make("start", rate=5.0), Command.make("set_rate", rate=math.nan),
                Command.make("set_rate", rate=-50.0), Command.make("set_rate", rate=1e9)):
        r = rogue.request("extruder", cmd, 3.0)
        assert refused(r.reason, r.ok), (cmd, r)
    assert logged(cell, "extruder", "start: the sender does not hold the cell's secret")
    for rate in (math.nan, -50.0, 1e9, math.inf):  # the operator's own: the range holds too
        for verb in ("start", "set_rate"):
            r = client.bus().request("extruder", Command.make(verb, rate=rate), 3.0)
            assert not r.ok and "outside [" in r.reason, (verb, rate, r)
    assert logged(cell, "extruder", "outside [0.01, 100]")
    time.sleep(0.3)
    with watch.lock:
        assert watch.extruder and not any(m.running for m in watch.extruder[-20:])


def test_forged_events_faults_and_abort_do_not_touch_a_print(
        cell: Launch, client: CellClient, rogue: Bus, tmp_path: Path) -> None:
    model = synthetic.write_cube(tmp_path / "cube.stl")
    job = client.submit(model)
    client.confirm_ready(job.id)
    end = time.monotonic() + 60
    while client.status(job.id).state != "printing" and time.monotonic() < end:
        time.sleep(0.02)
    while client.status(job.id).waypoint < 3 and time.monotonic() < end:
        time.sleep(0.02)
    forged_wp = 10**6
    for _ in range(5):
        rogue.publish_to("robot", "waypoint", WaypointReached(job.id, forged_wp, 99, 10**7,
                                                              time.time()))
        rogue.publish_to("robot", "event", StreamEvent(job.id, "done", "", 10**7, time.time()))
        rogue.publish_to("extruder", "state", ExtruderState(
            time.time(), 10**9, 0.0, 0.0, 0.0, False, True, FAULT_STALL, "forged fault"))
        time.sleep(0.02)
    r = rogue.request("supervisor", Command.make("abort", job.id), 3.0)
    assert refused(r.reason, r.ok), r
    assert client.status(job.id).waypoint != forged_wp
    done = client.wait(job.id, timeout=60)
    assert done.state == "done", (done.state, done.reason)
    assert done.waypoint == synthetic.LAYERS * synthetic.PER_LAYER - 1
    assert logged(cell, "supervisor", "robot/waypoint: unsigned")
    assert logged(cell, "supervisor", "robot/event: unsigned")
    assert logged(cell, "robot", "extruder/state: unsigned")
    assert logged(cell, "supervisor", "abort: the sender does not hold the cell's secret")


def test_a_session_with_another_secret_is_a_stranger(cell: Launch, tmp_path: Path) -> None:
    """Another user's own cell secret signs, but not for this cell."""
    other = session(cell, "supervisor", b"x" * 32, Role.NODE)
    try:
        r = other.request("extruder", Command.make("start", rate=5.0), 3.0)
        # the extruder's refusal is signed with the cell's secret: the stranger cannot even
        # trust that answer
        assert not r.ok
        assert logged(cell, "extruder", "not signed with this cell's secret")
    finally:
        other.close()


def test_files_a_job_may_not_name(client: CellClient, tmp_path: Path) -> None:
    os.symlink("/etc/shadow", tmp_path / "shadow.stl")
    with pytest.raises(InputError, match="outside its folder"):
        client.submit(tmp_path / "shadow.stl")
    (client.home / "import").mkdir(exist_ok=True)
    inside = client.home / "import" / "shadow.stl"
    inside.unlink(missing_ok=True)
    os.symlink("/etc/shadow", inside)
    with pytest.raises(InputError, match="outside the import folder"):
        client.store.submit(inside, "sim")
    model = synthetic.write_cube(tmp_path / "cube.stl")
    job_file = tmp_path / "job.toml"
    stray = tmp_path / "stray.toml"  # a readable, valid profile, but not in a profile folder
    stray.write_text(Path("slicer/profiles/ecoflex-0030.toml").read_text())
    job_file.write_text(f'[extrusion]\nprofile = "{stray}"\n')
    with pytest.raises(InputError, match="not in a profile folder"):
        client.submit(model, job_file)
    with pytest.raises(TypeError):
        JobStore.submit(client.store, model, "sim", job_id="../../x")  # type: ignore[call-arg]


def test_forged_supervisor_presence_does_not_keep_a_print_running(
        cell: Launch, client: CellClient, rogue: Bus, watch: Watch, tmp_path: Path) -> None:
    fake = session(cell, "supervisor", None)  # the supervisor's name, no secret
    fake.announce()  # its liveliness token, as the real one's
    fake.publish("heartbeat", Heartbeat("supervisor", "active", 1, 1, time.time()))
    try:
        model = synthetic.write_cube(tmp_path / f"{SLOW_MODEL}.stl")
        job = client.submit(model)
        client.confirm_ready(job.id)
        end = time.monotonic() + 60
        while client.status(job.id).waypoint < 3 and time.monotonic() < end:
            time.sleep(0.02)
        assert client.status(job.id).state == "printing"
        t_kill = time.time()
        os.kill(cell.pid("supervisor"), signal.SIGKILL)
        end = time.monotonic() + 10
        while time.monotonic() < end and not (
                watch.robot is not None and watch.robot.stop_t > t_kill):
            time.sleep(0.02)
        assert watch.robot is not None and watch.robot.stop_t > t_kill, "the print ran on"
        latency = watch.robot.stop_t - t_kill
        print(f"robot stopped {latency:.2f} s after kill -9 of the supervisor, its presence "
              "forged")
        # the robot and the extruder node both watch the supervisor's presence: whichever
        # notices its loss first stops the print (the extruder's stop stops the arm too,
        # for its own reason), never the forged token keeping it running
        extruder_log = (cell.log_dir / "extruder.log").read_text(errors="replace")
        assert ("supervisor process lost" in watch.robot.stop_reason
                or "stopping the extruder: supervisor process lost" in extruder_log), \
            watch.robot.stop_reason
        # the launcher restarts the supervisor: its new session ends the old one's presence;
        # else the token alone lasts presence.TIMEOUT_S without signed heartbeats
        assert latency < TIMEOUT_S + 1.0
        assert logged(cell, "robot", "supervisor/heartbeat: unsigned")
    finally:
        fake.close()
