"""planner.plan_report: the typed record of unreachable samples the status is decided from."""

from __future__ import annotations

import numpy as np

from planner.cell import CellConfig
from planner.orientation import Orientation
from planner.plan_report import stats, unreachable
from planner.reach import ALPHA, COLLISION, NO_IK, OK, REASONS, Reach
from planner.samples import Samples


def _samples(waypoint: list[int]) -> Samples:
    M = len(waypoint)
    z = np.zeros((M, 3))
    return Samples(tcp=z, normal=z, tangent=z, waypoint=np.array(waypoint, np.int32),
                   extrude=np.ones(M, bool), speed=np.ones(M), height=np.ones(M), arrive=z)


def _orient(status: list[int], pair: list[int]) -> Orientation:
    M = len(status)
    return Orientation(q=np.zeros((M, 6)), axis=np.zeros((M, 3)), psi=np.zeros(M),
                       tilt=np.zeros(M), lean=np.zeros(M), status=np.array(status, np.int8),
                       pair=np.array(pair, np.int32), clearance=np.zeros(M))


def test_unreachable_waypoints_come_in_runs_of_one_reason(cell: CellConfig) -> None:
    reach = Reach(cell)
    # entry sample, waypoints 0-5 with an inserted sample after 2, exit sample
    wp = [-1, 0, 1, 2, -1, 3, 4, 5, -1]
    part = np.array([0, 1, 1, 1, 1, 1, 1, 1, 2], np.int8)
    status = [NO_IK, OK, NO_IK, NO_IK, ALPHA, COLLISION, COLLISION, OK, NO_IK]
    pair = [-1, -1, -1, -1, -1, 0, 1, -1, -1]
    u = unreachable(reach, _samples(wp), _orient(status, pair), part)
    assert u.count == 4  # waypoints 1, 2, 3, 4: not the entry's, exit's or inserted samples
    assert u.by_reason == {REASONS[NO_IK]: 2, REASONS[COLLISION]: 2}
    names = reach.collision.names
    assert u.runs == [
        {"first": 1, "last": 2, "reason": REASONS[NO_IK]},
        {"first": 3, "last": 3, "reason": f"{REASONS[COLLISION]} ({names[0]})"},
        {"first": 4, "last": 4, "reason": f"{REASONS[COLLISION]} ({names[1]})"},
    ]
    assert u.between_waypoints == 1  # the inserted sample of the toolpath; not the moves
    assert u.as_report() == {"count": 4, "by_reason": u.by_reason, "waypoints": u.runs,
                             "between_waypoints": 1}


def test_a_reached_plan_has_nothing_unreachable(cell: CellConfig) -> None:
    u = unreachable(Reach(cell), _samples([0, 1, -1, 2]), _orient([OK] * 4, [-1] * 4),
                    np.ones(4, np.int8))
    assert (u.count, u.by_reason, u.runs, u.between_waypoints) == (0, {}, [], 0)


def test_stats_of_nothing_is_empty_and_of_a_ramp_its_percentiles() -> None:
    assert stats(np.zeros(0)) == {}
    s = stats(np.arange(101.0))
    assert (s["min"], s["p5"], s["p50"], s["p95"], s["max"], s["mean"]) == (
        0.0, 5.0, 50.0, 95.0, 100.0, 50.0)
