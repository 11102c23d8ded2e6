"""The "plan" section of report.json and the plan's one-line messages.

``Unreachable`` is the typed record the planner decides the status from (the waypoints and
samples between them no pose reaches); ``plan_report`` writes the JSON-ready section (mm, s,
deg) from the stages; the messages name the first refused waypoint or sample and why.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np

from core.stages import Toolpath
from core.tolerance import tol
from planner import kinematics as kin
from planner.cell import CellConfig
from planner.entry import TRANSFER, SafeMove
from planner.flow import ASKED_SLACK, asked_acceleration
from planner.orientation import Orientation
from planner.placement import Placement
from planner.reach import COLLISION, OK, REASONS, Reach
from planner.refusal import cause_of
from planner.samples import Samples
from planner.status import CAUSES, Cause
from planner.timing import Timing
from planner.trajectory import Trajectory
from planner.upright import COMFORT, Upright


@dataclass(frozen=True)
class Unreachable:
    """Toolpath samples no pose reaches.

    Attributes:
        count: unreachable toolpath waypoints.
        by_reason: their count per reason (``reach.REASONS``), in order of appearance.
        runs: one entry per run of consecutive waypoints with one reason: first and last
            waypoint and the reason (with the colliding pair).
        between_waypoints: samples inserted between waypoints (long moves) that fail too.
    """

    count: int
    by_reason: dict[str, int]
    runs: list[dict[str, Any]]
    between_waypoints: int

    def as_report(self) -> dict[str, Any]:
        """The "unreachable" subsection of the plan report."""
        return {"count": self.count, "by_reason": dict(self.by_reason), "waypoints": self.runs,
                "between_waypoints": self.between_waypoints}


def unreachable(reach: Reach, samples: Samples, orient: Orientation, part: np.ndarray
                ) -> Unreachable:
    """The unreachable waypoints and between-waypoint samples of the toolpath's part
    (``part == 1``; the entry's and exit's are reported under "entry"/"exit")."""
    wp = samples.waypoint
    bad = (orient.status != OK) & (wp >= 0)
    reasons = [REASONS[int(s)] for s in orient.status[bad]]
    names = reach.collision.names
    # every unreachable waypoint, as runs of consecutive waypoints with one reason
    rows = np.flatnonzero(bad)
    key = orient.status[rows].astype(np.int64) * 100000 + np.maximum(orient.pair[rows], -1) + 1
    w = wp[rows]
    if len(rows):
        starts = np.flatnonzero(np.r_[True, (np.diff(w) != 1) | (np.diff(key) != 0)])
    else:
        starts = np.zeros(0, dtype=np.int64)
    ends = np.r_[starts[1:], len(rows)][: len(starts)] - 1
    detail: list[dict[str, Any]] = []
    for a, b in zip(starts, ends, strict=True):  # one entry per run, not per waypoint
        i = rows[a]
        r = REASONS[int(orient.status[i])]
        if orient.pair[i] >= 0 and orient.status[i] == COLLISION:
            r += f" ({names[orient.pair[i]]})"
        detail.append({"first": int(w[a]), "last": int(w[b]), "reason": r})
    between = (orient.status != OK) & (wp < 0) & (part == 1)
    return Unreachable(int(bad.sum()), dict(Counter(reasons)), detail, int(between.sum()))


def stats(x: np.ndarray) -> dict[str, float]:
    """min, p5, p50, p95, max and mean of ``x`` (empty: no keys)."""
    if not len(x):
        return {}
    p = np.percentile(x, [5, 50, 95])
    return {"min": float(x.min()), "p5": float(p[0]), "p50": float(p[1]),
            "p95": float(p[2]), "max": float(x.max()), "mean": float(x.mean())}



def unreachable_message(toolpath: Toolpath, reach: Reach, samples: Samples,
                         orient: Orientation, part: np.ndarray) -> tuple[str, Cause]:
    """The first unreachable waypoint, its layer, position and cause (``refusal.cause_of``)."""
    rows = np.flatnonzero((orient.status != OK) & (samples.waypoint >= 0) & (part == 1))
    i = int(rows[0])
    w = int(samples.waypoint[i])
    code = int(orient.status[i])
    pair = reach.collision.names[int(orient.pair[i])] if orient.pair[i] >= 0 else ""
    cause = cause_of(code, pair, samples.normal[i])
    x, y, z = (float(c) for c in toolpath.position[w])
    return (f"{len(rows)} waypoints unreachable, the first waypoint {w} (layer "
            f"{int(toolpath.layer[w])}, at {x:.1f}, {y:.1f}, {z:.1f} mm): {CAUSES[cause]}"
            + (f" ({pair})" if pair and code == COLLISION else "")), cause


def upright_report(up: Upright, orient: Orientation, main: np.ndarray) -> dict[str, Any]:
    """How many samples were turned towards vertical, how far, and the singularity margins
    on the layer normals and along the planned motion (``main``: (M,) bool, the toolpath's
    samples, without entry and exit)."""
    margin = kin.singularity_margin(orient.q[main])
    return {"samples": int(np.sum(up.angle > tol.floor)),
            "max_deg": round(float(np.degrees(up.angle.max())), 3) if len(up.angle) else 0.0,
            "comfort_margin": COMFORT,
            "margin_on_normal_min": round(float(up.margin.min()), 4) if len(up.margin) else 1.0,
            "margin_min": round(float(np.nanmin(margin)), 4) if margin.size else 1.0}


def between_status(reach: Reach, samples: Samples, orient: Orientation,
                    failing: np.ndarray) -> str:
    """The plan's status where every waypoint is reached but samples between them are not
    (a long move, or the arm swinging next to a singularity): how many, the first one's
    reason and the waypoint before it."""
    i = int(failing[0])
    before = samples.waypoint[: i + 1]
    after = int(before[before >= 0][-1]) if (before >= 0).any() else -1
    code = int(orient.status[i])
    reason = REASONS.get(code, "unknown")
    if code == COLLISION and orient.pair[i] >= 0:
        reason = f"collision of {reach.collision.names[int(orient.pair[i])]}"
    return (f"{failing.size} samples between waypoints unreachable, first after waypoint "
            f"{after}: {reason}")



def move_report(move: SafeMove, traj: Trajectory, rows: np.ndarray) -> dict[str, Any]:
    """The "entry"/"exit" section: status, safe height, plunge length, clearance, duration."""
    seg = move.segment
    line = seg != TRANSFER
    tcp = move.tcp[line]
    length = float(np.linalg.norm(np.diff(tcp, axis=0), axis=1).sum()) if len(tcp) > 1 else 0.0
    t = traj.t[rows]
    return {
        "status": "ok" if move.ok else move.reason,
        "samples": int(rows.sum()),
        "safe_z_mm": round(move.safe_z_mm, 3),
        "axis_move_mm": round(length, 3),
        "min_clearance_mm": float(np.nanmin(move.clearance)) if move.ok else None,
        "duration_s": float(t[-1] - t[0]) if len(t) > 1 else 0.0,
    }



def plan_report(
    toolpath: Toolpath, cell: CellConfig, reach: Reach, samples: Samples, orient: Orientation,
    timing: Timing, placement: Placement, traj: Trajectory, unreached: Unreachable,
    seconds: dict[str, float],
) -> dict[str, Any]:
    """The "plan" section of report.json (mm, s, deg)."""
    ex = samples.extrude
    traj_axis = orient.axis
    names = reach.collision.names
    clear = orient.clearance
    has_c = np.isfinite(clear)
    k = int(np.nanargmin(np.where(has_c, clear, np.inf))) if has_c.any() else -1
    # speed: actual TCP speed on the step after each sample vs target
    dt = np.diff(traj.t)
    step = np.linalg.norm(np.diff(traj.tcp, axis=0), axis=1)
    v_step = step / np.maximum(dt, tol.zero)
    ex_step = ex[:-1] & (step > tol.still)  # zero-length steps (repeated waypoints) have no speed
    # the toolpath speed varies linearly along a segment (resample), so a step's target is
    # the mean of its ends' speeds
    target_step = 0.5 * (samples.speed[:-1] + samples.speed[1:])
    ratio = v_step[ex_step] / np.maximum(target_step[ex_step], tol.zero)
    # over-deposition: constant extrusion C for longer than the toolpath speed asks; C is the
    # job's (its profile's, through eq. 4: W H v = C at every extruding waypoint)
    C = float(np.median((toolpath.width * toolpath.height * toolpath.speed)[toolpath.extrude])
              ) if toolpath.extrude.any() else 0.0
    planned = step[ex_step] / np.maximum(target_step[ex_step], tol.zero)
    extra = np.maximum(dt[ex_step] - planned, 0.0) * C
    slowed = ratio < 0.95
    asked = asked_acceleration(toolpath)
    q_deg = np.degrees(traj.q)
    lo, hi = np.array(cell.robot.joint_min_deg), np.array(cell.robot.joint_max_deg)
    acc = np.abs(np.diff(traj.qd, axis=0)) / np.maximum(dt, tol.zero)[:, None]
    out: dict[str, Any] = {
        "waypoints": len(toolpath),
        "samples": len(traj),
        "duration_s": traj.duration_s,
        "placement": {"offset_mm": list(placement.offset_mm), "yaw_deg": placement.yaw_deg,
                      "evaluated": placement.evaluated,
                      "checked_waypoints": placement.checked,
                      "waypoints_needing_tilt": placement.need_tilt,
                      "search_clearance_mm": placement.clearance_mm},
        "min_clearance_mm": float(clear[k]) if k >= 0 else None,
        "min_clearance_pair": names[orient.pair[k]] if k >= 0 and orient.pair[k] >= 0 else None,
        "min_clearance_time_s": float(traj.t[k]) if k >= 0 else None,
        "required_clearance_mm": cell.planning.clearance_mm,
        "alpha_deg": {**stats(traj.alpha[ex]),
                      "tilted_samples": int(np.sum(np.abs(orient.tilt[ex]) > tol.still)),
                      "tilt_max_deg": float(np.degrees(np.abs(orient.tilt).max()))},
        "lean_deg": {**stats(np.degrees(orient.lean[ex])),
                     "leaned_samples": int(np.sum(np.abs(orient.lean[ex]) > tol.still)),
                     "lean_max_deg": float(np.degrees(np.abs(orient.lean).max())),
                     "limit_deg": cell.planning.lean_max_deg},
        "deviation_deg": stats(np.degrees(np.arccos(np.clip(
            -np.einsum("ij,ij->i", traj_axis[ex], samples.normal[ex]), -1.0, 1.0)))),
        "joint_margin_deg": {
            "min_to_lower": list(np.round(q_deg.min(axis=0) - lo, 3)),
            "min_to_upper": list(np.round(hi - q_deg.max(axis=0), 3)),
        },
        "joint_velocity_peak_fraction": list(np.round(
            np.abs(traj.qd).max(axis=0) / np.radians(cell.robot.max_velocity_deg_s), 4)),
        "joint_acceleration_peak_fraction": list(np.round(
            acc.max(axis=0) / np.radians(cell.robot.max_acceleration_deg_s2), 4))
        if len(acc) else [0.0] * 6,
        "speed_ratio": {**stats(ratio),
                        "within_5pct": float(np.mean(np.abs(ratio - 1) <= 0.05))
                        if len(ratio) else 1.0,
                        # the same by extruded length (short steps at a turn weigh less)
                        "within_5pct_length": float(
                            np.sum(step[ex_step] * (np.abs(ratio - 1) <= 0.05))
                            / max(float(step[ex_step].sum()), tol.zero)) if len(ratio) else 1.0},
        # the speed changes the toolpath asks for against the acceleration the cell gives
        # the slicer for them (``flow.asked_acceleration``)
        "path_accel": {"limit_mm_s2": cell.planning.path_accel_mm_s2,
                       "segments_over": int(np.sum(asked > cell.planning.path_accel_mm_s2
                                                   * (1.0 + ASKED_SLACK))),
                       "max_asked_mm_s2": float(asked.max()) if len(asked) else 0.0},
        "over_deposition": {
            "volume_mm3": float(extra.sum()),
            "fraction": float(extra.sum() / max(C * planned.sum(), tol.zero)),
            "slowed_steps": int(slowed.sum()),
            "max_local_factor": float(1.0 / max(ratio.min(), tol.zero)) if len(ratio) else 1.0,
        },
        "unreachable": unreached.as_report(),
        "time_law": {"status": timing.status, "iterations": timing.iterations},
        "timing_s": {k2: round(v, 4) for k2, v in seconds.items()},
    }
    return out
