"""Refusals name the real cause: a bend, a downward printing direction, reach, a wall."""

from __future__ import annotations

import numpy as np
import pytest

from planner.cell import CellConfig
from planner.placement import choose_placement
from planner.reach import ALPHA, COLLISION, NO_IK, Reach
from planner.refusal import bends, cause_of, waypoint_steps
from planner.status import CAUSES, FIXES, Cause, Refused
from tests.planner import synthetic


def test_every_cause_has_a_text_and_a_fix() -> None:
    assert set(CAUSES) == set(Cause) and set(FIXES) == set(Cause)


def test_cause_of_names_the_cause() -> None:
    up = np.array([0.0, 0.0, 1.0])
    assert cause_of(ALPHA, "", up) == Cause.BEND
    assert cause_of(NO_IK, "", up) == Cause.REACH
    assert cause_of(COLLISION, "extruder vs tank_wall_+x", up) == Cause.WALL
    assert cause_of(COLLISION, "extruder vs gel", up) == Cause.GEL
    assert cause_of(COLLISION, "forearm vs table", up) == Cause.OBSTACLE
    assert cause_of(ALPHA, "", -up) == Cause.DOWNWARD  # facing down comes first


def test_flat_paths_have_no_bends(cell: CellConfig) -> None:
    tp = synthetic.dome(radius=30.0, cap=6.0, rings=3, step=1.0)
    found = bends(tp, cell)
    assert len(found.waypoint) == 0


def test_steps_are_the_arriving_and_leaving_ones(cell: CellConfig) -> None:
    tp = synthetic.lines(n_lines=2, length=4.0, step=1.0)
    steps = waypoint_steps(tp, cell)
    assert np.allclose(steps.leave[0], [1.0, 0.0, 0.0])
    assert np.allclose(steps.arrive[0], 0.0)  # the first waypoint of a path: nothing arrives
    assert np.allclose(steps.arrive[4], [1.0, 0.0, 0.0])  # the last: the step arriving
    assert steps.extrude.all()


def test_a_downward_printing_direction_is_refused_as_such(cell: CellConfig) -> None:
    # a ring whose printing direction points down (an underside with a top critical region
    # forced onto it): no placement and no cell prints it from below
    ring = synthetic.rings(20.0, [5.0], [0.0])
    tp = synthetic.make_toolpath(ring.position, -ring.normal, ring.path)
    with pytest.raises(Refused) as err:
        choose_placement(Reach(cell), tp)
    assert err.value.cause == Cause.DOWNWARD
    assert "points downward" in err.value.problem and "layer 0" in err.value.problem
    assert "tried" in err.value.problem  # what the search tried
