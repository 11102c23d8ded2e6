"""Arguments checked at the receiving node: extruder rates finite and in range, a trajectory
that keeps the cell's clearance, a stream that starts where the arm is."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from mesp_cell.command_checks import (
    clearance_refusal,
    rate_range,
    rate_refusal,
    stream_refusal,
)
from mesp_cell.messages import Command
from planner.cell import load_cell
from planner.collision import CollisionModel


@pytest.mark.parametrize("rate", [math.nan, math.inf, -50.0, -1e-9, 1e9, "5", None, True])
def test_bad_rates_are_refused(rate: object) -> None:
    for verb in ("start", "set_rate"):
        assert rate_refusal(Command.make(verb, rate=rate)), (verb, rate)


def test_a_start_needs_a_set_point_and_flow_sync_may_slow_to_zero() -> None:
    assert "outside [0.01, " in rate_refusal(Command.make("start", rate=0.0))
    assert rate_refusal(Command.make("set_rate", rate=0.0)) == ""


def test_rates_in_range_pass_and_the_range_comes_from_the_ranges_file() -> None:
    lo, hi = rate_range()
    assert 0 < lo < 6.57 < hi  # the paper's C lies inside
    for rate in (lo, 6.57, hi):
        assert rate_refusal(Command.make("start", rate=rate)) == ""
    assert rate_refusal(Command.make("stop")) == ""


def test_clearance_of_a_trajectory() -> None:
    cell = load_cell(None)
    model = CollisionModel(cell)
    home = np.radians(cell.robot.home_deg)
    q = home + np.linspace(0, 1, 50)[:, None] * np.radians([20, 0, 0, 0, 0, 0])
    assert clearance_refusal(q, model, cell.planning.clearance_mm) == ""
    down = home + np.linspace(0, 1, 50)[:, None] * np.radians([0, 180, 0, 0, 0, 0])
    why = clearance_refusal(down, model, cell.planning.clearance_mm)
    assert "mm from the cell" in why and "under the required" in why
    assert "not finite" in clearance_refusal(np.full((3, 6), np.nan), model, 3.0)


def test_a_stream_must_start_at_the_arm(tmp_path: Path) -> None:
    home = np.radians([0.0, -90.0, 90.0, -90.0, -90.0, 0.0])
    plan = SimpleNamespace(samples=10, q_at=lambda k: home + np.radians([2.0 * k, 0, 0, 0, 0, 0]))
    node = SimpleNamespace(plan=plan, job_id="j",
                           driver=SimpleNamespace(joints=lambda: home))
    assert stream_refusal(node, Command.make("stream", "j", start=0)) == ""
    why = stream_refusal(node, Command.make("stream", "j", start=5))
    assert "10.0 deg from the arm's pose (joint 1)" in why
    assert "not a sample" in stream_refusal(node, Command.make("stream", "j", start=99))
    assert "not a sample" in stream_refusal(node, Command.make("stream", "j", start=1.5))
