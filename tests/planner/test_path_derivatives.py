"""Path derivatives: junctions where deposition stops and starts, windows not across them."""

from __future__ import annotations

import numpy as np

from planner.path_derivatives import junctions, neighbours, window_derivative


def test_junctions_mark_where_deposition_stops_and_starts() -> None:
    ex = np.array([1, 1, 0, 0, 1, 1, 1, 0], dtype=bool)
    # step 1 -> 2 deposits, 2 -> 3 does not: stop at 2; start at 4 (step 4 -> 5 deposits)
    assert junctions(ex).tolist() == [0, 0, -1, 0, 1, 0, 0, -1]
    assert not junctions(np.ones(5, dtype=bool)).any()


def test_neighbours_are_one_sided_at_junctions_and_ends() -> None:
    side = np.array([0, 0, -1, 1, 0], dtype=np.int8)
    nxt, prv = neighbours(5, side)
    assert nxt.tolist() == [1, 2, 2, 4, 4]
    assert prv.tolist() == [0, 0, 1, 3, 3]


def test_the_curvature_window_does_not_reach_across_a_junction() -> None:
    # q' steps from 0 to 1 right after sample 5, where deposition stops: the window of a
    # depositing sample before it sees none of the step, the samples after it all of it
    s = np.arange(0.0, 10.01, 0.25)
    y = (s > 5.0).astype(float)[:, None]
    side = np.zeros(len(s), dtype=np.int8)
    k = int(np.flatnonzero(s == 5.0)[0])
    side[k] = -1
    plain = window_derivative(y, s, 0.5)
    cut = window_derivative(y, s, 0.5, side)
    before = s <= 5.0
    assert plain[before].max() > 0.4  # the window across the stop spreads the step back
    assert np.allclose(cut[before], 0.0)
    # a start (+1) cuts the same way from the other side
    side[k] = 1
    y2 = (s >= 5.0).astype(float)[:, None]
    assert np.allclose(window_derivative(y2, s, 0.5, side)[s >= 5.0], 0.0)
