"""The ink at rest: the screw's time at rest counted on the extruder's flow clock (the twin's
shared simulated time, the wall clock on the real cell), the lead's deposition, the sum in the
job's report."""

from __future__ import annotations

import time
from pathlib import Path
from types import SimpleNamespace
from typing import cast

import numpy as np
import pytest

from mesp_cell.drivers.robot_base import ServoConfig
from mesp_cell.drivers.robot_twin import KinematicTwin
from mesp_cell.drivers.sim_clock import SimClock
from mesp_cell.drivers.stream import StreamPlan
from mesp_cell.nodes.ink_at_rest import RestTimer, add_rest_ink, deposition_s, rest_ink


def test_rest_time_on_the_twin_is_its_simulated_time_at_40x(tmp_path: Path) -> None:
    """The supervisor reads the clock the twin and the emulated extruder share: a pause of
    the twin (it lagged) is no time at rest, where wall time x 40 counted it 40 times over."""
    path = tmp_path / "sim.clock"
    owner = SimClock(40.0, path, reset=True)  # the emulator's
    twin = KinematicTwin(ServoConfig(time_scale=40.0), clock=SimClock(40.0, path))
    supervisor = SimClock(40.0, path)
    timer = RestTimer(supervisor, 40.0)
    wall = RestTimer(None, 40.0)
    sim0 = twin.sim_now()
    time.sleep(0.05)
    twin.clock.pause(0.03)  # the twin stood still for 30 ms of this wall time
    time.sleep(0.03)
    rest, by_wall, sim = timer.seconds(), wall.seconds(), twin.sim_now() - sim0
    assert rest == pytest.approx(sim, abs=40 * 0.002)  # the twin's own time, to a read's lag
    assert by_wall - rest == pytest.approx(40 * 0.03, abs=40 * 0.005)
    for c in (owner, twin.clock, supervisor):
        c.close()


def test_rest_time_on_the_real_cell_is_wall_time() -> None:
    timer = RestTimer(None, 1.0)
    t0 = time.monotonic()
    time.sleep(0.02)
    assert timer.seconds() == pytest.approx(time.monotonic() - t0, abs=0.005)


def test_deposition_in_the_lead_and_the_report_sum(tmp_path: Path) -> None:
    extrude = np.zeros(100, dtype=bool)
    extrude[10:50] = True
    plan = cast(StreamPlan, SimpleNamespace(extrude=extrude, dt=0.01, samples=100))
    # lead 0.2 s = 20 samples after sample 5: samples 6..25, of which 10..25 deposit
    assert deposition_s(plan, 5, 0.2) == pytest.approx(0.16)
    # from 5 up to the lead past a stop at 45: samples 6..65, of which 10..49 deposit
    assert deposition_s(plan, 5, 0.2, 45) == pytest.approx(0.40)
    add_rest_ink(tmp_path, 1.5)
    add_rest_ink(tmp_path, 0.25)
    assert rest_ink(tmp_path) == pytest.approx(1.75)
