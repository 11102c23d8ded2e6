"""Why a job cannot be printed, found before any pose is searched where geometry decides.

Alpha is the angle between the nozzle axis and each depositing step, at both of the step's
ends (``samples.resample``: the leaving and the arriving step of a waypoint). The nozzle may
deviate from the printing direction only by the tilts and leans ``orientation_levels``
offers. Where a path bends against its layer, no such axis keeps alpha within range on both
steps, at any placement, in any cell with the same alpha range: ``bends`` finds these
waypoints on the whole toolpath at once (vectorised over waypoints x candidate axes; only the
waypoints the printing direction itself does not serve are tested) and the alpha range that
would serve them (a fix checked by the same test). ``cause_of`` names the cause of a refused
pose in the user's terms (``status.Cause``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from core.stages import Toolpath
from planner.cell import CellConfig
from planner.nozzle_axis import alpha_of, alpha_within, nozzle_axis
from planner.orientation import orientation_levels
from planner.reach import ALPHA, COLLISION
from planner.samples import resample
from planner.status import Cause

BEND_BATCH = 1 << 18  # (waypoint, axis) pairs per block of the bend test


class Steps(NamedTuple):
    """The depositing steps at each waypoint, in the model frame.

    Attributes:
        leave: (N, 3) float64, unit direction of the step leaving the waypoint where it
            deposits, else of the depositing step arriving, else the path's tangent.
        arrive: (N, 3) float64, unit direction of the depositing step arriving at the
            waypoint, zero rows where none deposits.
        extrude: (N,) bool, some step at the waypoint deposits (alpha applies).
    """

    leave: np.ndarray
    arrive: np.ndarray
    extrude: np.ndarray


def waypoint_steps(toolpath: Toolpath, cell: CellConfig) -> Steps:
    """The steps of every waypoint as ``samples.resample`` defines them (identity placement)."""
    s = resample(toolpath, np.eye(4), cell)
    at = s.waypoint >= 0
    arrive = s.arrive[at]
    extrude = s.extrude[at] | (np.linalg.norm(arrive, axis=1) > 0.5)
    return Steps(s.tangent[at], arrive, extrude)


class Bends(NamedTuple):
    """Waypoints no nozzle axis serves (``bends``).

    Attributes:
        waypoint: (B,) int64, toolpath indices, ascending.
        needed_deg: (B,) float64, deg, the smallest half-width of an alpha range around
            90 deg that some candidate axis keeps on both steps of the waypoint.
        turn_deg: (B,) float64, deg, the angle between the arriving and the leaving step.
        tested: waypoints the printing direction alone did not serve (the ones tested).
    """

    waypoint: np.ndarray
    needed_deg: np.ndarray
    turn_deg: np.ndarray
    tested: int


def bends(toolpath: Toolpath, cell: CellConfig, steps: Steps | None = None) -> Bends:
    """The waypoints where no candidate nozzle axis keeps alpha in range on both steps."""
    steps = waypoint_steps(toolpath, cell) if steps is None else steps
    n = toolpath.normal / np.linalg.norm(toolpath.normal, axis=1, keepdims=True)
    has_arrive = np.linalg.norm(steps.arrive, axis=1) > 0.5
    ok0 = alpha_within(cell, -n, steps.leave, steps.extrude, steps.arrive)
    rows = np.flatnonzero(~ok0)
    empty = np.zeros(0)
    if not len(rows):
        return Bends(rows.astype(np.int64), empty, empty, 0)
    levels = orientation_levels(cell, alpha_of(-n[rows], steps.leave[rows]))
    L = len(levels)
    served = np.zeros(len(rows), dtype=bool)
    need = np.full(len(rows), 90.0)
    per = max(1, BEND_BATCH // L)
    for a in range(0, len(rows), per):  # blocks of waypoints, each against every axis
        r = rows[a:a + per]
        rr = np.repeat(r, L)
        ax = nozzle_axis(n[rr], steps.leave[rr], np.tile(levels[:, 0], len(r)),
                         np.tile(levels[:, 1], len(r)))
        dev = np.abs(np.degrees(alpha_of(ax, steps.leave[rr])) - 90.0)
        dev_a = np.where(has_arrive[rr],
                         np.abs(np.degrees(alpha_of(ax, steps.arrive[rr])) - 90.0), 0.0)
        worst = np.maximum(dev, dev_a).reshape(len(r), L)
        ok = alpha_within(cell, ax, steps.leave[rr], steps.extrude[rr], steps.arrive[rr])
        served[a:a + per] = ok.reshape(len(r), L).any(axis=1)
        need[a:a + per] = worst.min(axis=1)
    bad = rows[~served]
    turn = np.where(has_arrive[bad], np.degrees(alpha_of(steps.arrive[bad], steps.leave[bad])),
                    0.0)
    return Bends(bad.astype(np.int64), need[~served], turn, len(rows))


def downward(normal: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(N,) bool: printing directions (N, 3) pointing below the horizontal of ``up`` (3,)."""
    return np.asarray(normal @ up < 0.0)


def cause_of(code: int, pair: str, normal: np.ndarray, up: np.ndarray | None = None) -> Cause:
    """The user's-terms cause of a pose failing with reason ``code`` (orientation codes),
    closest collision pair name ``pair``, printing direction ``normal`` (3,) in a frame whose
    up is ``up`` (default +z)."""
    up = np.array([0.0, 0.0, 1.0]) if up is None else up
    if float(np.dot(normal, up)) < 0.0:
        return Cause.DOWNWARD
    if code == ALPHA:
        return Cause.BEND
    if code == COLLISION:
        if "tank_wall" in pair:
            return Cause.WALL
        if "gel" in pair or "tank_floor" in pair:
            return Cause.GEL
        return Cause.OBSTACLE
    return Cause.REACH
