"""Trajectory checks, resampling, the servo loop on the twin, and the interlock mask."""

from __future__ import annotations

import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from core.artifacts import save_npz
from core.errors import InputError
from mesp_cell.drivers.robot_base import ServoConfig, ur5e_flange
from mesp_cell.drivers.robot_twin import KinematicTwin
from mesp_cell.drivers.stream import ServoStream, StreamPlan, sha256_of
from mesp_cell.nodes.interlock import MustRun, must_run_mask
from tests.mesp_cell import synthetic

N_WP = synthetic.LAYERS * synthetic.PER_LAYER


@pytest.fixture
def job(tmp_path: Path) -> Path:
    synthetic.toolpath().save(tmp_path)
    save_npz(tmp_path / "trajectory.npz", synthetic.trajectory_arrays(N_WP))
    return tmp_path


#: s, the servo overrun watchdog of the twins here: a loaded 2-core host stalls a servo loop for
#: over a second now and then (its default 0.1 s stopped these streams); the watchdog is
#: test_a_stalled_servo_loop_stops_the_stream's subject
LOADED_OVERRUN_S = 10.0


def fast_twin(overrun_s: float = LOADED_OVERRUN_S) -> KinematicTwin:
    return KinematicTwin(ServoConfig(time_scale=1000.0, overrun_s=overrun_s), q0=synthetic.HOME)


def test_resampling_keeps_every_waypoint_in_order(job: Path) -> None:
    plan = StreamPlan.load(job / "trajectory.npz", 0.002, sha256_of(job / "trajectory.npz"))
    arrays = synthetic.trajectory_arrays(N_WP)
    duration = arrays["t"][-1]
    assert plan.samples == round(duration / 0.002) + 1
    assert np.array_equal(plan.wp_id, np.arange(N_WP))
    assert np.all(np.diff(plan.wp_sample) > 0)
    # Waypoint i is at t = sample_i / 100 Hz -> servo sample 5 * that trajectory sample.
    src = np.flatnonzero(arrays["waypoint"] >= 0)
    assert np.array_equal(plan.wp_sample, src * 5)
    assert np.allclose(plan.q[::5], arrays["q"][: plan.samples // 5 + 1])
    assert np.array_equal(plan.wp_layer, np.repeat(np.arange(synthetic.LAYERS),
                                                   synthetic.PER_LAYER))
    assert plan.sample_of_waypoint(-1) == 0 and plan.sample_of_waypoint(3) == src[3] * 5


def _swing_on_a_depositing_step(a: dict[str, np.ndarray]) -> None:
    """The base turns 29 deg between two depositing samples, slowly enough for its speed
    limit: linear in joint space, the nozzle would sweep an arc off the straight step."""
    k = int(np.flatnonzero(a["extrude"][:-1] & a["extrude"][1:])[10])
    a["q"][k + 1:, 0] += 0.5
    a["t"][k + 1:] += 10.0


@pytest.mark.parametrize("mutate, message", [
    (lambda a: a["q"].__setitem__((5, 2), np.nan), "NaN"),
    (lambda a: a["q"].__setitem__((5, 2), 7.0), "beyond the UR5e limit"),
    (lambda a: a["q"].__setitem__((slice(50, None), 0), a["q"][50:, 0] + 0.5), "deg/s"),
    (lambda a: a["t"].__setitem__(3, a["t"][2]), "does not increase"),
    (lambda a: a["waypoint"].__setitem__(0, 50), "not increasing"),
    (_swing_on_a_depositing_step, "leave the path"),
])
def test_bad_trajectories_are_refused_before_motion(tmp_path: Path, mutate, message) -> None:  # type: ignore[no-untyped-def]
    arrays = synthetic.trajectory_arrays(N_WP)
    mutate(arrays)
    save_npz(tmp_path / "trajectory.npz", arrays)
    with pytest.raises(InputError, match=message) as err:
        StreamPlan.load(tmp_path / "trajectory.npz", 0.002)
    assert "\n" not in err.value.one_line()


def test_changed_or_missing_files_are_refused(job: Path) -> None:
    with pytest.raises(InputError, match="sha256"):
        StreamPlan.load(job / "trajectory.npz", 0.002, "0" * 64)
    with pytest.raises(InputError, match="does not exist"):
        StreamPlan.load(job / "nothing.npz", 0.002)
    (job / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(InputError, match="not a readable"):
        StreamPlan.load(job / "bad.npz", 0.002)


def test_stream_reports_each_waypoint_once_across_a_stop_and_resume(job: Path) -> None:
    plan = StreamPlan.load(job / "trajectory.npz", 0.002)
    twin = fast_twin()
    twin.connect()
    seen: list[int] = []
    stop_at = int(plan.wp_sample[25]) + 2
    first = ServoStream(twin, plan, 0, guard=lambda k: "halt" if k == stop_at else "",
                        on_waypoint=lambda i: seen.append(int(plan.wp_id[i]))).run()
    assert not first.done and first.reason == "halt" and first.last_sample == stop_at - 1
    checkpoint = seen[-1]
    assert checkpoint == 25
    start = plan.sample_of_waypoint(checkpoint)
    second = ServoStream(twin, plan, start, after_waypoint=checkpoint,
                         on_waypoint=lambda i: seen.append(int(plan.wp_id[i]))).run()
    assert second.done and second.last_sample == plan.samples - 1
    assert seen == list(range(N_WP))
    assert twin.stop_times and len(twin.stop_times) == 2  # servoStop ends every stream
    # The twin tracks with a first-order lag tau = lookahead * 75 / gain: its error is at most
    # the commanded joint speed times tau.
    tau = twin.servo.lookahead_s * 75 / twin.servo.gain
    speed = np.abs(np.diff(plan.q, axis=0)).max() / plan.dt
    assert np.max(np.abs(twin.joints() - plan.q[-1])) <= 1.05 * speed * tau


def test_protective_stop_and_link_loss_end_the_stream(job: Path) -> None:
    plan = StreamPlan.load(job / "trajectory.npz", 0.002)
    twin = fast_twin()
    twin.connect()

    def pstop(k: int) -> None:
        if k == 100:
            twin.inject_protective_stop()

    result = ServoStream(twin, plan, 0, on_sample=pstop).run()
    assert result.reason == "protective stop" and result.last_sample == 100
    twin.clear_protective_stop()
    twin.inject_link_loss()
    result = ServoStream(twin, plan, 0).run()
    assert "link" in result.reason and result.last_sample == -1
    assert twin.reconnect() and twin.move_j(synthetic.HOME)


def test_a_stalled_servo_loop_stops_the_stream(job: Path) -> None:
    plan = StreamPlan.load(job / "trajectory.npz", 0.002)
    twin = fast_twin(overrun_s=1.0)  # longer than a loaded host's stalls, shorter than this one
    twin.connect()

    def stall(k: int) -> None:
        if k == 10:
            time.sleep(1.5 * twin.servo.overrun_s)

    result = ServoStream(twin, plan, 0, on_sample=stall).run()
    assert not result.done and "watchdog" in result.reason and result.last_sample == 10


def test_must_run_mask() -> None:
    extrude = np.array([0, 0, 1, 1, 1, 1, 1, 0, 0, 1, 1, 1], bool)
    # lead 2: switch-on at 0 (for 2), off at 5 (for 7), on again at 7 (for 9);
    # margin 1: the sample right after a switch-on is not yet required.
    mask = must_run_mask(extrude, lead_n=2, margin_n=1, start=0)
    expected = np.array([0, 0, 1, 1, 1, 0, 0, 0, 0, 1, 1, 1], bool)
    assert np.array_equal(mask, expected)
    assert not np.any(mask & ~extrude)


def test_must_run_mask_short_travel_within_the_margin() -> None:
    # Paths separated by 2-sample travel moves, margin 4: a switch-on less than 4 samples
    # old is never required, even though the sample 4 back was inside the previous path.
    extrude = np.array([1, 1, 1, 1, 1, 0, 0, 1, 1, 1, 1, 1, 1, 1, 0, 0, 1, 1], bool)
    mask = must_run_mask(extrude, lead_n=1, margin_n=4, start=0)
    cmd_on = extrude[np.minimum(np.arange(extrude.size) + 1, extrude.size - 1)]
    off = np.flatnonzero(~cmd_on)
    for k in np.flatnonzero(mask):
        assert cmd_on[k] and extrude[k]
        assert all(k - o - 1 >= 4 for o in off if o < k), k
    # Running since the start (the supervisor started it): required at once, until the
    # first switch-off lead; after each travel move only once the margin has passed.
    assert np.array_equal(np.flatnonzero(mask), [0, 1, 2, 3, 10, 11, 12])


def test_a_fast_twin_keeps_its_time_scale_without_spinning(job: Path) -> None:
    plan = StreamPlan.load(job / "trajectory.npz", 0.002)
    twin = KinematicTwin(ServoConfig(time_scale=10.0, overrun_s=LOADED_OVERRUN_S),
                         q0=synthetic.HOME)
    twin.connect()
    nominal = plan.samples * plan.dt / 10.0
    t0, c0 = time.perf_counter(), time.thread_time()
    result = ServoStream(twin, plan, 0).run()
    wall, cpu = time.perf_counter() - t0, time.thread_time() - c0
    assert result.done
    assert wall > 0.95 * nominal, (wall, nominal)
    # A 200 us period: the loop sleeps in batches (releasing the GIL) instead of spinning.
    assert cpu < 0.6 * wall, (cpu, wall)


def test_flange_kinematics_home_pose() -> None:
    # All joints zero: the UR5e arm stretched along -x; flange at x = a2 + a3, y = -(d4 + d6),
    # z = d1 - d5.
    T = ur5e_flange(np.zeros(6))
    assert np.allclose(T[:3, 3], [-817.2, -232.9, 62.8], atol=1e-6)
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3))


def test_mujoco_backend_tracks_the_stream(job: Path) -> None:
    from mesp_cell.drivers.robot_twin import mujoco_twin
    from planner import kinematics as kin
    from planner.cell import load_cell

    plan = StreamPlan.load(job / "trajectory.npz", 0.002)
    twin = mujoco_twin(ServoConfig(time_scale=1000.0, overrun_s=LOADED_OVERRUN_S),
                       q0=synthetic.HOME)
    twin.connect()
    errors: list[float] = []
    result = ServoStream(twin, plan, 0, on_sample=lambda k: errors.append(
        float(np.max(np.abs(twin.joints() - plan.q[k]))))).run()
    assert result.done
    assert max(errors) < 0.01  # rad: position + velocity actuators follow without lag
    tool = load_cell().tool.tool_T.copy()
    tool[:3, 3] /= 1000.0
    expected = kin.fk(twin.joints()[None], tool)[0, :3, 3] * 1000.0
    assert np.allclose(twin.tcp_mm(), expected, atol=0.5)  # mm, same kinematics as planner


def test_robot_node_moves_into_the_gel_only_along_the_nozzle_axis(tmp_path: Path) -> None:
    """Resume approach: from a stop in the gel the robot node moves to another sample on a
    checked safe path (retract along the axis, transfer above the gel, plunge) and arrives."""
    from mesp_cell.bus.session import BusConfig
    from mesp_cell.messages import Command
    from mesp_cell.nodes.robot_node import RobotNode
    from planner import kinematics as kin
    from planner.cell import load_cell
    from planner.placement import fit_gel
    from planner.plan import plan
    from planner.reach import Reach
    from tests.planner import synthetic as planner_synthetic

    cell = load_cell()
    tp = planner_synthetic.dome(radius=30.0, cap=6.0, rings=3, step=1.0)
    result = plan(tp, cell)
    tp.save(tmp_path)
    result.trajectory.save(tmp_path)
    node = RobotNode("robot", BusConfig(), {"backend": "twin",
                                            "servo": {"time_scale": 1000.0}})
    node.on_configure()
    try:
        assert np.allclose(node.home, np.radians(cell.robot.home_deg))
        reply = node._on_command(Command.make("load", "j", path=str(tmp_path / "trajectory.npz")))
        assert reply.ok, reply.reason
        plan_q = node.plan.q  # type: ignore[union-attr]
        ex = np.flatnonzero(node.plan.extrude)  # type: ignore[union-attr]
        stop_at, resume_at = int(ex[len(ex) * 3 // 4]), int(ex[len(ex) // 4])
        node.driver.q = plan_q[stop_at].copy()  # type: ignore[attr-defined]
        path, why = node._safe_path(plan_q[resume_at])
        assert path is not None and why == ""
        reach = Reach(fit_gel(cell, tp))
        gel = float((np.linalg.inv(cell.robot.base_T) @ cell.tank.floor_T)[2, 3]
                    + reach.cell.tank.gel_fill_mm)
        col = reach.collision
        a, b = col.segments(path.q)
        parts = [i for i, c in enumerate(col.capsules) if c.tool and c.name != "nozzle"]
        radius = np.array([col.capsules[i].radius for i in parts])
        lowest = (np.minimum(a[:, parts, 2], b[:, parts, 2]) - radius).min() * 1000.0
        assert lowest >= gel  # only the shaft is ever in the gel
        assert col.clearance(path.q).distance.min() >= cell.planning.clearance_mm - 0.5
        # below the gel surface the tip moves along the stop's or the target's nozzle axis
        T = kin.fk(path.q, reach.tool_m)
        tip = T[:, :3, 3] * 1000.0
        low = tip[:, 2] < gel
        axes = {tuple(np.round(kin.fk(plan_q[k], reach.tool_m)[:3, 2], 6))
                for k in (stop_at, resume_at)}
        assert {tuple(np.round(x, 6)) for x in T[low, :3, 2]} <= axes
        # the move itself, on the twin
        reply = node._on_command(Command.make("move", "j", to="sample", sample=resume_at))
        assert reply.ok, reply.reason
        assert node._motion is not None
        node._motion.join(30.0)
        assert node.mode == "idle"
        assert np.abs(node.driver.joints() - plan_q[resume_at]).max() < 1e-3
        # already there: a zero move
        path, why = node._safe_path(plan_q[resume_at] + 1e-6)
        assert path is None and why == ""
    finally:
        node.on_shutdown()


def _reference_resampling(a: dict[str, np.ndarray], dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Every servo sample built at once, as the streamer did before it interpolated on demand."""
    t = a["t"] - a["t"][0]
    K = int(np.floor(t[-1] / dt + 1e-9)) + 1
    tk = dt * np.arange(K)
    q = np.stack([np.interp(tk, t, a["q"][:, j]) for j in range(6)], axis=1)
    src = np.clip(np.searchsorted(t, tk, side="right") - 1, 0, len(t) - 1)
    return q, a["extrude"][src]


def test_servo_samples_on_demand_equal_the_whole_resampling(job: Path) -> None:
    dt = 0.0023  # not a divisor of the trajectory's sample period
    plan = StreamPlan.load(job / "trajectory.npz", dt)
    arrays = synthetic.trajectory_arrays(N_WP)
    q, extrude = _reference_resampling(arrays, dt)
    assert plan.samples == len(q) == len(plan.q) == len(plan.extrude)
    assert np.allclose(np.asarray(plan.q), q, atol=1e-12)
    assert np.array_equal(np.asarray(plan.extrude), extrude)
    ks = [0, 1, 7, len(q) // 2, len(q) - 1]
    assert all(np.allclose(plan.q_at(k), q[k], atol=1e-12) for k in ks)
    assert all(plan.extrude_at(k) == extrude[k] for k in ks)
    assert np.allclose(plan.q[-1], q[-1]) and np.allclose(plan.q[3:40:6], q[3:40:6])
    assert plan.first_extruding() == int(np.argmax(extrude))
    with pytest.raises(IndexError):
        plan.q[len(q)]


def test_must_run_chunk_by_chunk_equals_the_whole_mask(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(MustRun, "CHUNK", 7)
    rng = np.random.default_rng(5)
    for trial in range(40):
        K = int(rng.integers(5, 120))
        extrude = np.repeat(rng.random(K // 3 + 1) < 0.6, 3)[:K]
        lead_n, margin_n = int(rng.integers(0, 5)), int(rng.integers(0, 6))
        start = int(rng.integers(0, K))
        whole = must_run_mask(extrude, lead_n, margin_n, start)
        must = MustRun(extrude, lead_n, margin_n, start)
        got = [must(k) for k in range(start, K)]
        assert np.array_equal(got, whole[start:]), trial
    must = MustRun(np.ones(30, bool), 1, 1, 0)
    must(10)
    with pytest.raises(ValueError):  # a stream only moves forward
        must(0)


def test_a_thirty_hour_job_loads_without_building_its_servo_samples(tmp_path: Path) -> None:
    # 30 h at 500 Hz: 54 M servo samples (2.6 GB of joint targets as an array)
    M = 200_000
    t = np.linspace(0.0, 30 * 3600.0, M)
    s = np.sin(2 * np.pi * t / t[-1])[:, None]
    q = synthetic.HOME + 0.15 * s * np.array([1.0, 0.5, -0.5, 0.3, 0.2, 0.1])
    wp = np.arange(M, dtype=np.int32)
    save_npz(tmp_path / "trajectory.npz", {
        "t": t, "q": q, "qd": np.gradient(q, t, axis=0), "tcp": np.zeros((M, 3)), "waypoint": wp,
        "alpha": np.full(M, 90.0), "extrude": np.ones(M, bool), "base_T": np.eye(4),
        "tool_T": np.eye(4), "model_T": np.eye(4)})
    tracemalloc.start()
    plan = StreamPlan.load(tmp_path / "trajectory.npz", 0.002)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert plan.samples == 54_000_001
    assert peak < 200e6  # the joint targets as an array alone would be 2.6 GB
    k = plan.samples - 12_345
    assert np.allclose(plan.q_at(k), [np.interp(k * 0.002, t, q[:, j]) for j in range(6)])
    must = MustRun(plan.extrude, 25, 50, k)
    assert all(must(i) for i in range(k + 50, k + 100))


def test_flow_sync_commands_the_rate_of_the_step_ahead() -> None:
    from dataclasses import replace

    from mesp_cell.nodes.flow_sync import FLOW_STEP, FlowSync

    # 4 s of trajectory; from t = 2 to 3 s the arm moves at half the toolpath's speed
    plan = StreamPlan.of_path(0.1, np.arange(5.0), np.zeros((5, 6)), np.eye(4))
    plan = replace(plan, flow_knots=np.array([1.0, 1.0, 0.5, 1.0, 1.0]))
    assert plan.flow_at(19) == 1.0 and plan.flow_at(20) == 0.5 and plan.flow_at(30) == 1.0
    sync = FlowSync(plan, rate=6.0, lead_n=3, end=plan.samples, interval_n=2, start=0)
    sent = {k: r for k in range(plan.samples) if (r := sync(k)) is not None}
    # lead 3 samples: half the rate from sample 17, back to C from sample 27
    assert sent == {17: pytest.approx(3.0), 27: pytest.approx(6.0)}
    # a switch-on commands the rate of the step ahead at once
    again = FlowSync(plan, rate=6.0, lead_n=3, end=plan.samples, interval_n=2, start=0)
    assert again.switch_on(18) == pytest.approx(3.0)
    assert again(19) is None  # within the interval
    # changes within FLOW_STEP of C are not sent; the interval holds back the next command
    small = replace(plan, flow_knots=np.array([1.0, 1.0 - 0.5 * FLOW_STEP, 1.0, 0.2, 0.9]))
    quiet = FlowSync(small, rate=6.0, lead_n=0, end=small.samples, interval_n=15, start=0)
    got = {k: r for k in range(small.samples) if (r := quiet(k)) is not None}
    assert got == {30: pytest.approx(1.2)}  # 0.9 C at sample 40 comes within the interval
    assert quiet(45) == pytest.approx(5.4)


def test_a_plan_with_its_toolpath_gets_the_flow_scale(job: Path) -> None:
    from planner.flow import MIN_FLOW_SCALE

    plan = StreamPlan.load(job / "trajectory.npz", 0.002)
    assert plan.flow_knots.shape == plan.t.shape
    assert plan.flow_knots.min() >= MIN_FLOW_SCALE and plan.flow_knots.max() <= 1.0
    alone = job / "alone"
    alone.mkdir()
    (alone / "trajectory.npz").write_bytes((job / "trajectory.npz").read_bytes())
    assert np.all(StreamPlan.load(alone / "trajectory.npz", 0.002).flow_knots == 1.0)
