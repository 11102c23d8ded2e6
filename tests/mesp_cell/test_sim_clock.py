"""The simulated cell's clock: shared between processes, paused by a lagging twin, and the
emulated extruder's flow counted on it."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from mesp_cell.drivers import registers as R
from mesp_cell.drivers import robot_twin
from mesp_cell.drivers.extruder_plant import ExtruderPlant, PlantParams
from mesp_cell.drivers.robot_base import ServoConfig
from mesp_cell.drivers.robot_twin import KinematicTwin
from mesp_cell.drivers.sim_clock import SimClock
from tests.mesp_cell import synthetic


def test_a_shared_clock_is_seen_by_every_attached_reader(tmp_path: Path) -> None:
    path = tmp_path / "run" / "sim.clock"
    owner = SimClock(40.0, path, reset=True)
    twin = SimClock(40.0, path)
    twin.pause(0.25)
    twin.pause(-1.0)  # never runs the clock forward
    assert owner.paused() == pytest.approx(0.25)
    assert owner.now(10.0) == pytest.approx(40.0 * 9.75)
    assert owner.wall_at(owner.now(12.5)) == pytest.approx(12.5)
    # A restarted twin attaches to the clock as it is; a new launch resets it.
    assert SimClock(40.0, path).paused() == pytest.approx(0.25)
    assert SimClock(40.0, path, reset=True).paused() == 0.0 == twin.paused()
    assert SimClock(40.0).paused() == 0.0  # private
    # a writer killed mid-write (sequence left odd) does not hang its readers
    import struct

    with open(path, "r+b") as f:
        f.write(struct.pack("<Q", 7))
    assert owner.paused() == 0.0
    with pytest.raises(ValueError):
        SimClock(0.0)


class SlowTwin(KinematicTwin):
    """A twin whose every servo period costs ``cost_s`` of wall time (MuJoCo on a loaded
    host): far slower than its time scale asks."""

    cost_s = 0.001

    def _step(self, target: np.ndarray, dt: float) -> None:
        time.sleep(self.cost_s)
        super()._step(target, dt)


def test_a_lagging_twin_pauses_the_extruders_clock(tmp_path: Path) -> None:
    # 100x asks for 20 us per 2 ms period; the twin takes >= 1 ms. The extruder runs at a
    # constant rate for the motion on the shared clock: its volume is the rate times the
    # twin's own simulated time, not times 1000 x the wall time it took.
    path = tmp_path / "sim.clock"
    scale, rate, periods = 100.0, 6.0, 150
    params = PlantParams(tau_s=1e-4, watchdog_s=0.0, time_scale=scale)  # flow at once
    plant = ExtruderPlant(params, time.monotonic(), SimClock(scale, path, reset=True))
    private = ExtruderPlant(params, time.monotonic())
    twin = SlowTwin(ServoConfig(time_scale=scale), q0=synthetic.HOME,
                    clock=SimClock(scale, path))
    twin.connect()
    for p in (plant, private):
        p.set_rate(rate, time.monotonic())
        p.command(R.CMD_RUN, time.monotonic())
    volumes, w0 = [], time.monotonic()
    for _ in range(periods + 2):
        t0 = twin.init_period()
        twin.servo_j(synthetic.HOME)
        twin.wait_period(t0)
        plant.step(time.monotonic())
        private.step(time.monotonic())
        volumes.append((plant.volume, private.volume))
    twin.servo_stop()
    wall = time.monotonic() - w0
    simulated = periods * 0.002  # 0.3 s of motion after the first period
    assert wall > 30 * simulated / scale  # the twin really lagged
    assert twin.clock.paused() > 0.9 * wall
    shared, old = np.subtract(volumes[-1], volumes[1])  # the first period warms up
    # The plant reads the clock a few us after each period ends: at 100x, a few ms of flow; a
    # loaded host (the suite's other worker) delays a read by up to ~0.3 ms, 30 ms of flow.
    assert shared == pytest.approx(rate * simulated, abs=rate * 0.03)
    assert old > 10 * rate * simulated  # the old, private clock over-extrudes


def test_an_idle_twin_lets_simulated_time_run(tmp_path: Path) -> None:
    path = tmp_path / "sim.clock"
    twin = KinematicTwin(ServoConfig(time_scale=100.0), q0=synthetic.HOME,
                         clock=SimClock(100.0, path, reset=True))
    twin.connect()
    assert twin.move_j(synthetic.HOME + 0.01)
    clock = twin.clock
    paused, w0 = clock.paused(), clock.wall()
    time.sleep(0.05)  # at rest: nothing pauses the clock
    w1 = clock.wall()
    assert clock.paused() == paused
    assert clock.now(w1) - clock.now(w0) == pytest.approx(100.0 * (w1 - w0))
    with pytest.raises(ValueError):  # a clock of another speed is a launch mistake
        KinematicTwin(ServoConfig(time_scale=10.0), clock=SimClock(100.0))


def test_no_torn_read_under_contention() -> None:
    # A writer process pausing the clock non-stop, this process reading it: every value is a
    # whole one (a multiple of the writer's step) and never goes back (bench/bench_sim_clock.py
    # measures 2 M reads: the seqlock this replaced tore 3-29 of them).
    from bench.bench_sim_clock import contend

    out = contend(300_000, Path(__file__).resolve().parents[2], seconds=30.0)
    assert out.writes > 1000  # the writer really ran during the reads
    assert out.torn == 0, f"{out.torn} torn reads, worst jump {out.worst_s} s"


def test_a_writer_stopped_mid_write_leaves_the_published_value_whole(tmp_path: Path) -> None:
    path = tmp_path / "sim.clock"
    writer, reader = SimClock(1.0, path, reset=True), SimClock(1.0, path)
    writer.pause(2.0)
    # a writer killed while filling the next slot: half of its bytes in place, not published
    with open(path, "r+b") as f:
        f.seek(8)
        f.write(b"\xff" * 4)
    assert reader.paused() == 2.0
    writer.pause(float("nan"))  # ignored: the clock never breaks
    assert reader.paused() == 2.0


def test_a_hold_stops_every_reader_until_released_or_lapsed(tmp_path: Path) -> None:
    path = tmp_path / "sim.clock"
    writer, reader = SimClock(2.0, path, reset=True), SimClock(2.0, path)
    wall = writer.wall()
    writer.hold("twin", 2.0 * wall + 1.0, 10.0)
    writer.hold("switch", 2.0 * wall + 0.5, 10.0)  # the earliest hold is in force
    assert reader.now(wall + 5.0) == pytest.approx(2.0 * wall + 0.5)
    assert reader.now(wall + 0.1) == pytest.approx(2.0 * (wall + 0.1))  # below it: free
    writer.release("switch")
    assert reader.now(wall + 5.0) == pytest.approx(2.0 * wall + 1.0)
    assert reader.now(wall + 11.0) == pytest.approx(2.0 * (wall + 11.0))  # lapsed
    writer.hold("twin", 2.0 * wall + 1.0, 10.0, pause_s=0.25)  # one publication
    assert reader.paused() == pytest.approx(0.25)
    writer.release("twin")
    assert reader.now(wall + 5.0) == pytest.approx(2.0 * (wall + 4.75))
    # a restarted twin's clock holds nothing of its predecessor's once it writes
    writer.hold("twin", 0.0, 10.0)
    SimClock(2.0, path).pause(0.25)
    assert reader.now(wall + 5.0) == pytest.approx(2.0 * (wall + 4.5))


class FakeWall:
    """A wall clock the test moves: the twin's sleeps and the emulator's polls advance it."""

    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


@pytest.mark.parametrize("switch", ["on", "off"])
def test_a_twin_stalled_mid_period_moves_no_ink_across_a_switch(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, switch: str) -> None:
    # Real time (scale 1) on a loaded host: the twin's servo thread is descheduled for 130 ms,
    # 20 ms before it switches the screw on (or off), while the emulated extruder polls on
    # every 5 ms. The extruder must deliver the rate over the twin's own on-time: the old
    # clock, paused only once the twin ran again, let the extruder count the stall with the
    # screw off (on) and then wait while the twin caught up with it on (off): 110 ms of the
    # 0.5 s of flow lost (gained), as the synthetic print's -9 % under a loaded suite.
    wall = FakeWall()
    monkeypatch.setattr(SimClock, "wall", staticmethod(wall))
    monkeypatch.setattr(robot_twin, "precise_sleep_until",
                        lambda due: setattr(wall, "t", max(wall.t, due)))
    path = tmp_path / "sim.clock"
    rate, dt, stall_s, poll_s = 5.0, 0.002, 0.13, 0.005
    plant = ExtruderPlant(PlantParams(tau_s=1e-4, watchdog_s=0.0), wall(),
                          SimClock(1.0, path, reset=True))
    plant.set_rate(rate, wall())
    twin = KinematicTwin(ServoConfig(dt=dt, overrun_s=0.3), q0=synthetic.HOME,
                         clock=SimClock(1.0, path))
    twin.connect()
    on_k, off_k = 100, 350  # 0.5 s of flow
    stall_k = (on_k if switch == "on" else off_k) - 10
    for k in range(450):
        t0 = twin.init_period()
        twin.servo_j(synthetic.HOME)
        if k == stall_k:  # descheduled: the emulator polls on without the twin
            for _ in range(round(stall_s / poll_s)):
                wall.t += poll_s
                plant.step(wall())
        if k in (on_k, off_k):
            plant.command(R.CMD_RUN if k == on_k else 0, wall())
        twin.wait_period(t0)
        plant.step(wall())
    twin.servo_stop()
    wall.t += 1.0
    plant.step(wall())
    assert twin.clock.paused() == pytest.approx(stall_s - dt)  # the twin lagged (less its period)
    assert plant.volume == pytest.approx(rate * (off_k - on_k) * dt, rel=1e-3)


def test_the_twin_times_its_decisions_by_its_own_time_not_a_held_clock(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # At rest the twin's time is the shared clock's; in a motion it is its own periods x dt,
    # also while another writer (an extruder switch in flight) holds the clock back.
    wall = FakeWall()
    monkeypatch.setattr(SimClock, "wall", staticmethod(wall))
    monkeypatch.setattr(robot_twin, "precise_sleep_until",
                        lambda due: setattr(wall, "t", max(wall.t, due)))
    dt = 0.002
    clock = SimClock(1.0, tmp_path / "sim.clock", reset=True)
    twin = KinematicTwin(ServoConfig(dt=dt, overrun_s=0.3), q0=synthetic.HOME, clock=clock)
    twin.connect()
    assert twin.sim_now() == pytest.approx(clock.now())
    start = clock.now()
    for k in range(100):
        t0 = twin.init_period()
        twin.servo_j(synthetic.HOME)
        if k == 10:
            clock.hold("switch", clock.now(), 1.0)  # a switch in flight from here on
        twin.wait_period(t0)
    assert clock.now() == pytest.approx(start + 10 * dt)  # held
    assert twin.sim_now() == pytest.approx(start + 100 * dt)  # the twin's own time
    twin.servo_stop()
    clock.release("switch")
    assert twin.sim_now() == pytest.approx(clock.now())
