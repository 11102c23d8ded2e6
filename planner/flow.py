"""Extrusion synchronised with the planned motion: how fast the arm really moves each step.

The slicer sets a nozzle speed per waypoint and the filament's cross-section C / v from it
(paper eq. 4). The planner slows the arm where it cannot follow (sharp turns at speed, joint
limits: ``plan.speed_ratio``). An extruder pushing a constant C there lays more ink per
millimetre, in a fatter filament. The cell instead scales the extruder's rate with the arm
(what the paper's cell calls the synchronisation of motion and extrusion): C x the ratio of
the arm's speed to the toolpath's, so the ink per millimetre and the filament stay what the
slicer asked for. This module says what that ratio is, per toolpath segment
(``segment_speeds``) and per trajectory sample (``knot_flow_scale``); the robot node streams it
to the extruder (``mesp_cell.nodes.robot_node``) and the virtual print of the plan
(``sim.as_planned``) deposits with it. ``asked_acceleration`` says where the toolpath's own
speed changes ask more of the arm than the cell's path acceleration, which the slicer shapes
them to (``core.path_accel``).
"""

from __future__ import annotations

from typing import NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from core.stages import Toolpath
from core.tolerance import tol

# the lowest scale commanded: the arm stopping dead (a U-turn) still gets a trickle, so the
# extruder's screw keeps its pressure (its flow response is first order, tau ~0.2 s)
MIN_FLOW_SCALE = 0.02
# a toolpath segment asking at most this fraction more than the cell's path acceleration is
# not counted as asking more (``asked_acceleration``)
ASKED_SLACK = 0.01


class Timed(Protocol):
    """What these functions read of a trajectory (``planner.trajectory.Trajectory`` or the
    robot node's arrays): t (M,) s, waypoint (M,) int (-1 between waypoints), extrude (M,)
    bool."""

    @property
    def t(self) -> NDArray[np.float64]: ...

    @property
    def waypoint(self) -> NDArray[np.int32]: ...

    @property
    def extrude(self) -> NDArray[np.bool_]: ...


class PlannedSpeeds(NamedTuple):
    """Per toolpath segment i -> i + 1 (N - 1 of them, in toolpath order).

    speed: (N - 1,) float64, mm/s, segment length / time the trajectory takes for it.
    ratio: (N - 1,) float64, target_duration / duration: 1 where the arm keeps the
        toolpath's speed, below where it slows down; 1 for zero-length segments.
    duration: (N - 1,) float64, s, the time between the two waypoints' samples.
    target_duration: (N - 1,) float64, s, the time at the toolpath's speed, varying linearly
        along the segment from one waypoint's to the next's (the planner's target):
        L ln(v1 / v0) / (v1 - v0), L / v0 where they are equal.
    """

    speed: NDArray[np.float64]
    ratio: NDArray[np.float64]
    duration: NDArray[np.float64]
    target_duration: NDArray[np.float64]


def segment_speeds(toolpath: Toolpath, trajectory: Timed) -> PlannedSpeeds:
    """The speed ``trajectory`` moves each segment of ``toolpath`` at (see the module doc).

    Raises:
        InputError: the trajectory was not planned for this toolpath (its samples do not
            pass each waypoint once, in order).
    """
    n = len(toolpath)
    wp = np.asarray(trajectory.waypoint, dtype=np.int64)
    rows = np.flatnonzero(wp >= 0)
    if len(rows) != n or not np.array_equal(wp[rows], np.arange(n)):
        raise InputError(
            f"trajectory.npz passes {len(np.unique(wp[rows]))} waypoints, the toolpath has {n}: "
            "it was planned for another toolpath", "re-run mesp plan DIR")
    t = np.asarray(trajectory.t, dtype=np.float64)[rows]
    duration = np.diff(t)
    length = np.linalg.norm(np.diff(toolpath.position, axis=0), axis=1)
    v0, v1 = toolpath.speed[:-1], toolpath.speed[1:]
    moving = (length > 0.0) & (v0 > 0) & (v1 > 0)
    # time at a speed linear in arc length: integral of ds / v = L ln(v1 / v0) / (v1 - v0)
    a, b = np.maximum(v0, tol.zero), np.maximum(v1, tol.zero)
    close = np.abs(b - a) <= tol.slack * np.maximum(a, b)
    per_mm = np.where(close, 2.0 / (a + b),
                      np.log(b / a) / np.where(close, 1.0, b - a))
    target_duration = np.where(moving, length * per_mm, 0.0)
    # t increases strictly (Trajectory checks it), so every duration is positive
    speed = np.where(length > 0.0, length / np.maximum(duration, tol.zero), 0.5 * (v0 + v1))
    ratio = np.where(moving, target_duration / np.maximum(duration, tol.zero), 1.0)
    return PlannedSpeeds(speed=speed, ratio=ratio, duration=duration,
                         target_duration=target_duration)




def asked_acceleration(toolpath: Toolpath) -> NDArray[np.float64]:
    """(N - 1,) float64, mm/s^2, per toolpath segment, the largest nozzle acceleration its
    speed change asks for at the toolpath's speeds: the speed varies linearly along the
    segment, so v dv/dx peaks at the faster end, max(v0, v1) |v1 - v0| / L; 0 on segments
    that do not deposit or have no length. The slicer ramps its speed changes to the cell's
    ``path_accel_mm_s2`` (``core.path_accel``); a segment asking more is where the arm may
    fall behind the toolpath's speed (``plan_report``)."""
    if len(toolpath) < 2:
        return np.zeros(0)
    v = toolpath.speed
    length = np.linalg.norm(np.diff(toolpath.position, axis=0), axis=1)
    live = (toolpath.extrude[1:] & toolpath.extrude[:-1]
            & (toolpath.path[1:] == toolpath.path[:-1]) & (length > tol.zero))
    acc = np.maximum(v[1:], v[:-1]) * np.abs(np.diff(v)) / np.maximum(length, tol.zero)
    return np.where(live, acc, 0.0)


def knot_flow_scale(toolpath: Toolpath, trajectory: Timed,
                    planned: PlannedSpeeds | None = None) -> NDArray[np.float64]:
    """(M,) float64 in [MIN_FLOW_SCALE, 1], per trajectory sample, the extrusion rate over C
    that keeps the ink per millimetre on the step after it: the ``PlannedSpeeds.ratio`` of the
    toolpath segment the step belongs to (``planned``, or computed); 1 on steps that do not
    deposit and before the first waypoint.

    Raises:
        InputError: the trajectory was not planned for this toolpath.
    """
    ratio = (planned if planned is not None else segment_speeds(toolpath, trajectory)).ratio
    wp = np.asarray(trajectory.waypoint, dtype=np.int64)
    # the toolpath segment a step lies on: the last waypoint passed at or before its sample
    passed = np.maximum.accumulate(np.where(wp >= 0, wp, -1))
    seg = np.clip(passed, 0, max(len(ratio) - 1, 0))
    scale = np.ones(len(wp))
    on = np.asarray(trajectory.extrude, dtype=bool) & (passed >= 0) & (passed < len(ratio))
    if len(ratio):
        scale[on] = np.clip(ratio[seg[on]], MIN_FLOW_SCALE, 1.0)
    return scale
