"""Normals smoothed along each path by arc length: bounded, spacing-independent, per path, and
the reason it exists: a faceted layer's kinking normals no longer slow the nozzle."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from core.stages import Toolpath
from planner.cell import CellConfig
from planner.path_smoothing import smooth_along_paths
from planner.plan import plan
from tests.planner import synthetic
from tests.planner.synthetic import make_toolpath


def _kinked(step: float, kink_deg: float = 30.0) -> Toolpath:
    """One 20 mm line along x whose normal turns by ``kink_deg`` about y at x = 10 mm."""
    tp = synthetic.lines(n_lines=1, length=20.0, step=step)
    x = np.asarray(tp.position)[:, 0]
    a = np.radians(np.where(x >= 10.0 - 1e-9, kink_deg, 0.0))
    n = np.stack([np.sin(a), np.zeros_like(a), np.cos(a)], axis=1)
    return make_toolpath(np.array(tp.position), n, np.array(tp.path))


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", a, b), -1.0, 1.0)))


def test_a_kink_is_spread_over_millimetres_within_the_cap() -> None:
    tp = _kinked(0.5)
    out, turn = smooth_along_paths(tp, 3.0, 8.0)
    assert np.allclose(np.linalg.norm(out.normal, axis=1), 1.0)
    assert np.degrees(turn).max() <= 8.0 + 1e-9
    before = _angle_deg(tp.normal[1:], tp.normal[:-1]).max()
    after = _angle_deg(out.normal[1:], out.normal[:-1]).max()
    assert before == np.float64(30.0) or abs(before - 30.0) < 1e-6
    assert after < before / 2  # the 30 deg jump at one step is spread over several
    # 3 sigma from the kink the normals are left within 0.2 deg of what they were
    x = np.asarray(tp.position)[:, 0]
    assert np.degrees(turn[np.abs(x - 10.0) >= 9.0]).max() < 0.2


def test_the_smoothing_length_is_in_mm_not_waypoints() -> None:
    coarse, fine = _kinked(0.5), _kinked(0.1)
    a, turn_a = smooth_along_paths(coarse, 2.0, 20.0)
    b, turn_b = smooth_along_paths(fine, 2.0, 20.0)
    # the same positions (every 0.5 mm) get nearly the same directions (the kink itself
    # lies within one segment: 0.5 mm on the coarse line, 0.1 mm on the fine one)
    assert _angle_deg(a.normal, b.normal[::5]).max() < 2.0
    # and the kink is spread over the same length: five times as many fine waypoints
    spread_a = 0.5 * np.sum(np.degrees(turn_a) > 1.0)
    spread_b = 0.1 * np.sum(np.degrees(turn_b) > 1.0)
    assert abs(spread_a - spread_b) <= 1.0 and spread_a > 4.0


def test_paths_are_smoothed_apart_and_flat_layers_are_untouched() -> None:
    tp = synthetic.lines(n_lines=2, length=10.0, step=0.5)
    n = np.tile([0.0, 0.0, 1.0], (len(tp), 1))
    second = np.asarray(tp.path) == 1
    a = np.radians(20.0)
    n[second] = [np.sin(a), 0.0, np.cos(a)]  # the second path on a tilted layer
    out, turn = smooth_along_paths(make_toolpath(np.array(tp.position), n,
                                                 np.array(tp.path)), 3.0, 8.0)
    assert np.abs(turn).max() < 1e-9  # nothing carried from one path to the next
    assert np.allclose(out.normal, n)
    same, turn0 = smooth_along_paths(tp, 0.0, 8.0)
    assert same is tp and not turn0.any()


def test_kinking_normals_no_longer_slow_the_nozzle(cell: CellConfig) -> None:
    # A faceted layer: the normal kinks by +-6 deg about the line at every waypoint (0.75 mm
    # apart), as marching-tets layers of a real scan do. Followed exactly, the long tool
    # jerks the wrist at every waypoint and the joint accelerations slow the nozzle.
    tp = synthetic.lines(n_lines=3, length=40.0, step=0.75)
    k = np.arange(len(tp))
    a = np.radians(np.where(k % 2 == 0, 6.0, -6.0))
    n = np.stack([np.zeros_like(a), np.sin(a), np.cos(a)], axis=1)
    faceted = make_toolpath(np.array(tp.position), n, np.array(tp.path))
    exact = replace(cell, planning=replace(cell.planning, smooth_length_mm=0.0))
    slow = plan(faceted, exact)
    kept = plan(faceted, cell)
    assert slow.report["speed_ratio"]["within_5pct"] < 0.9
    assert kept.report["speed_ratio"]["within_5pct"] >= 0.95  # the target
    assert kept.status == "ok"
    alpha = kept.report["alpha_deg"]
    lo, hi = cell.planning.alpha_min_deg, cell.planning.alpha_max_deg
    assert lo <= alpha["min"] <= alpha["max"] <= hi
