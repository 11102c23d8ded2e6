"""The print as the planned trajectory moves the nozzle (``mesp inspect DIR --as-planned``).

The virtual print of ``toolpath.npz`` assumes the nozzle moves at the speeds the slicer set.
The planner slows down where the arm cannot follow them (sharp turns at speed, joint
acceleration limits: ``plan.speed_ratio`` in report.json). ``planner.flow.segment_speeds``
measures, per toolpath segment, the speed the trajectory actually moves it at and the ratio
to the planner's target. What the extruder does there decides the ink:

* ``constant`` flow: it keeps pushing C mm^3/s, so a segment that takes longer deposits more,
  C * dt instead of C * L / v, in a fatter filament (area C / v at the slower speed).
* ``synced`` flow (the cell's default, ``mesp_cell.nodes.robot_node``): the robot node commands
  C x the planned speed ratio (``planner.flow.knot_flow_scale``) ``lead_s`` ahead, and the
  screw follows with its first-order flow response (time constant ``tau_s``; the bundled
  launch files: lead 0.3 s, the emulated extruder's tau 0.2 s). ``synced_segment_ink``
  integrates that flow over each segment's time: the ink per millimetre stays the slicer's
  except within about tau of a change of speed. As before, switching the extruder on and off
  at the ends of paths is taken as exact (lead-compensated).

Either way each segment is printed at an effective speed C * L / ink
(``sim.deposition.deposit(..., segment_speed=...)``): the volume is the ink and the filament's
cross-section ink / L.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

from core.stages import Toolpath
from core.tolerance import tol
from planner.flow import PlannedSpeeds, knot_flow_scale, segment_speeds
from planner.trajectory import Trajectory
from sim.deposition import Morphology, extrusion_segments

__all__ = ["SLOWED", "Flow", "PlannedSpeeds", "Slowdown", "effective_speed", "segment_speeds",
           "slowdown", "synced_segment_ink"]

SLOWED = 0.95  # a segment moved at less than this x its toolpath speed counts as slowed
FLOW_DT_S = 0.01  # s, time step of the simulated flow response (longer on jobs over 11 h)
FLOW_STEPS_MAX = 4_000_000
Flow = Literal["synced", "constant"]


class Slowdown(NamedTuple):
    """The extruding segments of a toolpath as a trajectory moves them (print order).

    layer: (S,) int32; length: (S,) float64, mm; ratio: (S,) float64,
    ``PlannedSpeeds.ratio``; extra_mm3: (S,) float64, ink laid beyond what the segment
    asks for (C * target_duration): with constant flow C * (dt - target_duration), with
    synced flow what the lagging screw lays around changes of speed.
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
                float(self.length[slowed].sum() / max(float(self.length.sum()), tol.zero)),
                "speed_ratio_min": float(self.ratio.min()) if self.ratio.size else 1.0,
                "extra_ink_mm3": float(self.extra_mm3.sum())}


def synced_segment_ink(toolpath: Toolpath, trajectory: Trajectory, planned: PlannedSpeeds,
                       rate_mm3_s: float, lead_s: float = 0.3, tau_s: float = 0.2
                       ) -> NDArray[np.float64]:
    """(N - 1,) float64 mm^3, the ink a speed-synced extruder lays on each toolpath segment
    (module doc): the commanded rate C x ``knot_flow_scale``, ``lead_s`` ahead, through a
    first-order response ``tau_s``, integrated between the samples of the segment's two
    waypoints. Segments with zero duration get none."""
    t = np.asarray(trajectory.t, dtype=np.float64)
    scale = knot_flow_scale(toolpath, trajectory, planned)
    step = max(FLOW_DT_S, (t[-1] - t[0]) / FLOW_STEPS_MAX)
    grid = np.arange(t[0], t[-1] + step, step)
    # the command at time s is the scale of the step being moved at s + lead
    knot = np.clip(np.searchsorted(t, grid + lead_s, side="right") - 1, 0, len(t) - 1)
    command = rate_mm3_s * scale[knot]
    if tau_s > 0:
        a = float(np.exp(-step / tau_s))
        # exact for a command held over each step; starts settled at the first command
        flow, _ = lfilter([1.0 - a], [1.0, -a], command, zi=[a * command[0]])
    else:
        flow = command
    # ink laid from the start: the flow held over each grid step
    ink_at = np.concatenate([[0.0], np.cumsum(flow[:-1] * step)])
    cum = np.interp(t, grid, ink_at)
    rows = np.flatnonzero(np.asarray(trajectory.waypoint) >= 0)
    at_waypoint = cum[rows]  # one per toolpath waypoint, in order (segment_speeds checked it)
    ink: NDArray[np.float64] = np.maximum(np.diff(at_waypoint), 0.0)
    return ink


def effective_speed(toolpath: Toolpath, planned: PlannedSpeeds, ink: NDArray[np.float64],
                    rate_mm3_s: float) -> NDArray[np.float64]:
    """(N - 1,) mm/s, the speed at which a constant-rate extruder would lay ``ink`` on each
    segment: C * L / ink (the planned speed where a segment gets no ink)."""
    length = np.linalg.norm(np.diff(toolpath.position, axis=0), axis=1)
    out = planned.speed.copy()
    has = (ink > 0.0) & (length > 0.0)
    out[has] = rate_mm3_s * length[has] / ink[has]
    return out


def slowdown(toolpath: Toolpath, planned: PlannedSpeeds, morphology: Morphology,
             ink: NDArray[np.float64] | None = None) -> Slowdown:
    """Per extruding segment (``sim.deposition.extrusion_segments``), how the trajectory's
    speed changes what the toolpath asked for: constant flow without ``ink``, else the
    per-segment ink given (``synced_segment_ink``)."""
    seg = extrusion_segments(toolpath, morphology)
    i = seg.waypoint
    target = morphology.rate_mm3_s * planned.target_duration[i]
    laid = morphology.rate_mm3_s * planned.duration[i] if ink is None else ink[i]
    return Slowdown(layer=seg.layer, length=seg.length, ratio=planned.ratio[i],
                    extra_mm3=laid - target)

