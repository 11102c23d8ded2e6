"""The supervisor's waits for slicing and planning, sized to the job."""

from __future__ import annotations

from pathlib import Path

import pytest

from core.errors import InputError
from mesp_cell.step_timeouts import (
    MAX_WAIT_S,
    PLAN_BASE_S,
    PLAN_PER_WAYPOINT_S,
    SLICE_BASE_S,
    plan_timeout,
    slice_timeout,
)
from tests.mesp_cell import synthetic


def test_a_small_model_waits_minutes_not_an_hour(tmp_path: Path) -> None:
    small = slice_timeout(synthetic.write_cube(tmp_path / "s.stl", 10.0), None)
    large = slice_timeout(synthetic.write_cube(tmp_path / "l.stl", 80.0), None)
    assert SLICE_BASE_S < small < large < MAX_WAIT_S
    assert small < 600


def test_an_unreadable_model_fails_at_once(tmp_path: Path) -> None:
    bad = tmp_path / "bad.vtu"
    bad.write_bytes(b"<?xml \x00\xff")
    with pytest.raises(InputError, match="not a readable tet mesh"):
        slice_timeout(bad, None)


def test_planning_waits_by_the_waypoints(tmp_path: Path) -> None:
    synthetic.toolpath().save(tmp_path)
    n = len(synthetic.toolpath())
    assert plan_timeout(tmp_path) == pytest.approx(PLAN_BASE_S + PLAN_PER_WAYPOINT_S * n)
    assert plan_timeout(tmp_path / "missing") == PLAN_BASE_S
