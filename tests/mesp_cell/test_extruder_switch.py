"""The robot's extruder switches: sent in order, what a fast twin's latency moved recorded."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from mesp_cell.drivers import registers as R
from mesp_cell.drivers.extruder_plant import ExtruderPlant, PlantParams
from mesp_cell.drivers.sim_clock import SimClock
from mesp_cell.nodes import print_ledger
from mesp_cell.nodes.extruder_switch import Switcher


class Clock:
    """A flow clock the test moves by hand."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def plant_on_shared_clock(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, rate: float,
                          running: bool) -> tuple[Clock, ExtruderPlant, SimClock]:
    """A wall clock the test moves, an extruder plant (flow settles in 0.1 ms) at ``rate`` on
    the shared clock file, and the twin's view of that clock (scale 1)."""
    wall = Clock()
    wall.t = 1000.0
    monkeypatch.setattr(SimClock, "wall", staticmethod(wall))
    path = tmp_path / "sim.clock"
    plant = ExtruderPlant(PlantParams(tau_s=1e-4, watchdog_s=0.0), wall(),
                          SimClock(1.0, path, reset=True))
    plant.set_rate(rate, wall())
    plant.command(R.CMD_RUN if running else 0, wall())
    return wall, plant, SimClock(1.0, path)


def run_switches(time_scale: float, tmp_path: Path) -> tuple[list[tuple[str, float]], Clock]:
    clock = Clock()
    sent: list[tuple[str, float]] = []
    stopping = threading.Event()

    def send(verb: str, rate: float) -> str:
        clock.t += 0.1  # each request takes 0.1 s of the flow's clock
        sent.append((verb, rate))
        if verb == "stop" and len(sent) == 4:
            stopping.set()
        return "" if verb != "set_rate" else "refused"

    sw = Switcher(send, clock, time_scale)
    sw.put("stop", 5.0, -5.0, tmp_path)
    sw.put("start", 5.0, 5.0, tmp_path)
    sw.put("set_rate", 6.0, 1.0, tmp_path)  # refused: nothing recorded
    sw.put("stop", 0.0)  # a safety stop: not recorded
    sw.run(stopping)
    return sent, clock


def test_switches_go_in_order_and_a_fast_twin_records_their_excess(tmp_path: Path) -> None:
    print_ledger.Ledger(tmp_path, fresh=True).close()
    sent, _ = run_switches(40.0, tmp_path)
    assert [v for v, _ in sent] == ["stop", "start", "set_rate", "stop"]
    printed = print_ledger.read(tmp_path)
    # the stop was 0.1 s late (+5 x 0.1 of ink), the start 0.2 s (queued behind it: -5 x 0.2),
    # each less what real time would have moved (1 / 40 of it)
    assert printed.switches == 2
    assert printed.switch_mm3 == pytest.approx((0.5 - 1.0) * (1 - 1 / 40))


def test_real_time_records_nothing(tmp_path: Path) -> None:
    print_ledger.Ledger(tmp_path, fresh=True).close()
    run_switches(1.0, tmp_path)
    assert print_ledger.read(tmp_path).switches == 0


@pytest.mark.parametrize("verb", ["start", "stop"])
def test_on_the_twin_a_late_switch_lands_at_its_simulated_time(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, verb: str) -> None:
    # Real time (scale 1): the switch decided at 0.5 s of flow reaches the emulated extruder
    # 120 ms later (a loaded host: the switcher's thread, the bus, the extruder node), while
    # the extruder polls on every 5 ms. Holding the shared clock at the decision, the
    # extruder takes it at 0.5 s: 0.5 s of flow (of the 1 s it could run), not 0.62 (0.38).
    rate = 5.0
    wall, plant, twin_clock = plant_on_shared_clock(tmp_path, monkeypatch, rate, verb == "stop")
    stopping = threading.Event()

    def send(verb: str, rate: float) -> str:
        for _ in range(24):
            wall.t += 0.005
            plant.step(wall())
        plant.command(R.CMD_RUN if verb == "start" else 0, wall())
        stopping.set()
        return ""

    sw = Switcher(send, twin_clock.now, 1.0, twin_clock)
    wall.t += 0.5
    plant.step(wall())
    sw.put(verb, rate, rate if verb == "start" else -rate, tmp_path)
    sw.run(stopping)
    wall.t = 1001.0
    plant.step(wall())
    assert plant.volume == pytest.approx(rate * 0.5, rel=1e-3)
    assert twin_clock.now() == pytest.approx(1001.0)  # released: the clock runs on


def test_a_switch_decided_while_an_earlier_one_holds_the_clock_keeps_its_own_time(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # The twin stops the screw at 0.5 s and starts it again at 0.55 s (a short travel), and
    # each switch takes 120 ms to reach the extruder. While the stop holds the shared clock
    # at 0.5 s, the start is decided: timed by the twin's own time it lands at 0.55 s, so
    # the screw ran 0.5 + 0.45 s of the second; timed by the held clock it landed at 0.5 s
    # too and the screw ran through the travel (1.0 s).
    rate = 5.0
    wall, plant, twin_clock = plant_on_shared_clock(tmp_path, monkeypatch, rate, True)
    twin = Clock()  # the twin's own simulated time: it keeps pace with the wall here
    stopping = threading.Event()
    sent: list[str] = []

    def send(verb: str, rate: float) -> str:
        for _ in range(24):
            wall.t += 0.005
            plant.step(wall())
        plant.command(R.CMD_RUN if verb == "start" else 0, wall())
        sent.append(verb)
        if len(sent) == 2:
            stopping.set()
        return ""

    sw = Switcher(send, twin_clock.now, 1.0, twin_clock, decided=twin)
    wall.t = twin.t = 1000.5
    plant.step(wall())
    sw.put("stop", 0.0, -rate, tmp_path)
    wall.t = twin.t = 1000.55
    plant.step(wall())
    assert twin_clock.now() == pytest.approx(1000.5)  # held by the stop
    sw.put("start", rate, rate, tmp_path)
    sw.run(stopping)
    wall.t = 1001.0
    plant.step(wall())
    assert sent == ["stop", "start"]
    assert plant.volume == pytest.approx(rate * (0.5 + 0.45), rel=1e-3)
    assert twin_clock.now() == pytest.approx(1001.0)


def test_a_fast_twin_with_late_switches_delivers_its_plans_ink() -> None:
    # The real twin, switcher and extruder plant (its own process, on the shared clock) at
    # 40x, every switch up to 60 ms of wall time late (2.4 s of simulated flow): the ink is
    # the plan's (bench/bench_twin_ink.py; timed by the held clock it was +1.2 to +1.5 %).
    from bench.bench_twin_ink import run

    ink, planned = run(40.0, 6, 60.0, 0.0, seed=1, twin_time=True)
    assert ink == pytest.approx(planned, rel=1e-3)
