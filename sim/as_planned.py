"""The speed a planned trajectory moves the nozzle at along each toolpath segment.

The virtual print of ``toolpath.npz`` assumes the nozzle moves at the speeds the slicer set.
The planner slows down where the arm cannot follow them (sharp turns at speed, joint
acceleration limits: ``plan.speed_ratio`` in report.json) while the extruder keeps pushing
C mm^3/s, so a segment that takes longer deposits more: C * dt instead of C * L / v, in a
fatter filament (area C / v at the slower speed). ``segment_speeds`` measures, per toolpath
segment, the speed the trajectory actually moves it at: the segment's length over the time
between the samples of its two waypoints; and how that time compares with the planner's own
target, the toolpath speed varying linearly along the segment (``target_duration``: on a long
segment between a slow and a fast waypoint that is longer than L over the mean speed, and the
arm is not slowed for taking it). ``sim.deposition.deposit(..., segment_speed=...)``
prints with it (``mesp inspect DIR --as-planned``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from planner.trajectory import Trajectory
from sim.deposition import Morphology, extrusion_segments
from slicer.errors import InputError
from slicer.stages import Toolpath

SLOWED = 0.95  # a segment moved at less than this x its toolpath speed counts as slowed


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


def segment_speeds(toolpath: Toolpath, trajectory: Trajectory) -> PlannedSpeeds:
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
    a, b = np.maximum(v0, 1e-12), np.maximum(v1, 1e-12)
    close = np.abs(b - a) <= 1e-9 * np.maximum(a, b)
    per_mm = np.where(close, 2.0 / (a + b),
                      np.log(b / a) / np.where(close, 1.0, b - a))
    target_duration = np.where(moving, length * per_mm, 0.0)
    # t increases strictly (Trajectory checks it), so every duration is positive
    speed = np.where(length > 0.0, length / np.maximum(duration, 1e-12), 0.5 * (v0 + v1))
    ratio = np.where(moving, target_duration / np.maximum(duration, 1e-12), 1.0)
    return PlannedSpeeds(speed=speed, ratio=ratio, duration=duration,
                         target_duration=target_duration)


class Slowdown(NamedTuple):
    """The extruding segments of a toolpath as a trajectory moves them (print order).

    layer: (S,) int32; length: (S,) float64, mm; ratio: (S,) float64,
    ``PlannedSpeeds.ratio``; extra_mm3: (S,) float64, ink the extruder lays while the arm
    runs behind the planner's target, C * (dt - target_duration).
    """

    layer: NDArray[np.int32]
    length: NDArray[np.float64]
    ratio: NDArray[np.float64]
    extra_mm3: NDArray[np.float64]

    def summary(self) -> dict[str, float]:
        """``slowed_length_fraction`` (below SLOWED x its speed), ``speed_ratio_min`` and
        ``extra_ink_mm3`` (report.json's inspect.as_planned)."""
        slowed = self.ratio < SLOWED
        return {"slowed_length_fraction":
                float(self.length[slowed].sum() / max(float(self.length.sum()), 1e-12)),
                "speed_ratio_min": float(self.ratio.min()) if self.ratio.size else 1.0,
                "extra_ink_mm3": float(self.extra_mm3.sum())}


def slowdown(toolpath: Toolpath, planned: PlannedSpeeds, morphology: Morphology) -> Slowdown:
    """Per extruding segment (``sim.deposition.extrusion_segments``), how the trajectory's
    speed and the constant-rate extruder change what the toolpath asked for."""
    seg = extrusion_segments(toolpath, morphology)
    i = seg.waypoint
    extra = morphology.rate_mm3_s * (planned.duration[i] - planned.target_duration[i])
    return Slowdown(layer=seg.layer, length=seg.length, ratio=planned.ratio[i], extra_mm3=extra)
