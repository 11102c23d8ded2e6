"""Toolpath -> timed UR5e joint trajectory: the ``mesp plan`` pipeline as a library call.

Stages: placement (search the model's place in the tank), resample (insert samples on long
segments), orientation (spin and alpha per sample), velocity (DLS joint rates), timing (time law
within joint limits), report. ``plan`` returns the ``Trajectory`` stage and the report section.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np

from planner import kinematics as kin
from planner.cell import CellConfig
from planner.orientation import COLLISION, OK, REASONS, Orientation, Reach, alpha_of, choose, unit
from planner.placement import Placement, choose_placement, waypoint_tangents
from planner.timing import Timing, angular_rates, task_rates, time_law
from planner.trajectory import Trajectory
from slicer.errors import InputError
from slicer.progress import Progress, StageTimer
from slicer.stages import Toolpath


@dataclass(frozen=True)
class Samples:
    """The toolpath resampled in the robot base frame.

    Attributes:
        tcp: (M, 3) float64, mm, target nozzle tip positions.
        normal: (M, 3) float64, unit printing directions.
        tangent: (M, 3) float64, unit motion directions.
        waypoint: (M,) int32, toolpath index, -1 for inserted samples.
        extrude: (M,) bool, deposit on the step to the next sample.
        speed: (M,) float64, mm/s, target TCP speed.
        height: (M,) float64, mm, layer height (for over-deposition).
    """

    tcp: np.ndarray
    normal: np.ndarray
    tangent: np.ndarray
    waypoint: np.ndarray
    extrude: np.ndarray
    speed: np.ndarray
    height: np.ndarray


@dataclass(frozen=True)
class PlanResult:
    """Everything ``plan`` produced.

    Attributes:
        trajectory: the stage written to trajectory.npz.
        report: the "plan" section of report.json.
        samples, orientation, timing, placement: intermediate values (for plots and tests).
        clearance: (M,) float64, mm, clearance along the trajectory (nan where not sampled).
        status: "ok", or "unreachable waypoints" / the time law's status.
    """

    trajectory: Trajectory
    report: dict[str, Any]
    samples: Samples
    orientation: Orientation
    timing: Timing
    placement: Placement
    clearance: np.ndarray
    status: str


def resample(toolpath: Toolpath, model_T: np.ndarray, cell: CellConfig) -> Samples:
    """Map waypoints into the base frame and insert samples so no step exceeds max_step_mm."""
    R = model_T[:3, :3]
    P = toolpath.position @ R.T + model_T[:3, 3]
    Nn = unit(toolpath.normal @ R.T)
    T = waypoint_tangents(toolpath.position, toolpath.path) @ R.T
    N = len(P)
    planning = cell.planning
    if N == 1:
        return Samples(P, Nn, T, np.zeros(1, np.int32), np.zeros(1, bool),
                       np.full(1, planning.travel_speed_mm_s), toolpath.height.copy())
    seg = P[1:] - P[:-1]
    length = np.linalg.norm(seg, axis=1)
    inner = toolpath.path[1:] == toolpath.path[:-1]
    seg_extrude = toolpath.extrude[:-1] & toolpath.extrude[1:] & inner
    v = toolpath.speed
    seg_v0 = np.where(inner & (v[:-1] > 0), v[:-1], planning.travel_speed_mm_s)
    seg_v1 = np.where(inner & (v[1:] > 0), v[1:], planning.travel_speed_mm_s)
    count = np.maximum(np.ceil(length / planning.max_step_mm).astype(np.int64), 1)
    seg_of = np.repeat(np.arange(N - 1), count)
    first = np.concatenate([[0], np.cumsum(count)[:-1]])
    k = np.arange(len(seg_of)) - first[seg_of]
    f = k / count[seg_of]
    tcp = np.concatenate([P[seg_of] + f[:, None] * seg[seg_of], P[-1:]])
    normal = np.concatenate(
        [unit(Nn[seg_of] * (1 - f[:, None]) + Nn[seg_of + 1] * f[:, None]), Nn[-1:]]
    )
    seg_dir = unit(seg)
    # waypoints keep their path direction; inserted samples move along their segment
    tangent = np.where((k == 0)[:, None], T[seg_of], seg_dir[seg_of])
    tangent = np.concatenate([tangent, T[-1:]])
    bad = np.linalg.norm(tangent, axis=1) < 0.5
    tangent[bad] = np.concatenate([seg_dir, seg_dir[-1:]])[np.minimum(
        np.concatenate([seg_of, [N - 2]])[bad], N - 2)]
    waypoint = np.concatenate([np.where(k == 0, seg_of, -1), [N - 1]]).astype(np.int32)
    extrude = np.concatenate([seg_extrude[seg_of], [False]])
    speed = np.concatenate([seg_v0[seg_of] * (1 - f) + seg_v1[seg_of] * f, [seg_v1[-1]]])
    h = toolpath.height
    height = np.concatenate([h[seg_of] * (1 - f) + h[seg_of + 1] * f, h[-1:]])
    return Samples(tcp, normal, tangent, waypoint, extrude, speed, height)


ROTATION_MM_PER_RAD = 50.0  # tool rotation counted as path length where the TCP stays


def path_parameter(tcp_mm: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Generalised arc length s (M,) mm: per step the TCP travel, or ROTATION_MM_PER_RAD
    times the tool rotation angle for steps where the TCP stays put (never zero)."""
    if len(tcp_mm) < 2:
        return np.zeros(len(tcp_mm))
    step = np.linalg.norm(np.diff(tcp_mm, axis=0), axis=1)
    rel = np.einsum("kji,kjl->kil", R[:-1], R[1:])  # R_k^T R_{k+1}
    cos = np.clip((np.trace(rel, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    # TCP travel where the TCP moves (so |dp/ds| = 1 and speeds are exact); rotation only
    # where it does not
    ds = np.where(step > 1e-3, step, np.maximum(ROTATION_MM_PER_RAD * np.arccos(cos), 1e-6))
    return np.concatenate([[0.0], np.cumsum(ds)])


def _stats(x: np.ndarray) -> dict[str, float]:
    if not len(x):
        return {}
    p = np.percentile(x, [5, 50, 95])
    return {"min": float(x.min()), "p5": float(p[0]), "p50": float(p[1]),
            "p95": float(p[2]), "max": float(x.max()), "mean": float(x.mean())}


def plan(
    toolpath: Toolpath, cell: CellConfig, progress: Progress | None = None,
    placement: Placement | None = None,
) -> PlanResult:
    """Plan the whole job (see module docstring).

    Raises:
        InputError: an empty toolpath, or no placement reaches the job.
    """
    if len(toolpath) == 0:
        raise InputError("the toolpath has no waypoints", "re-run `mesp slice`")
    if not np.all(np.isfinite(toolpath.position)) or not np.all(np.isfinite(toolpath.normal)):
        raise InputError("the toolpath holds non-finite positions or normals",
                         "re-run `mesp slice`")
    timer = StageTimer(progress)
    reach = Reach(cell)
    with timer.stage("placement"):
        if placement is None:
            placement = choose_placement(reach, toolpath)
    with timer.stage("resample"):
        samples = resample(toolpath, placement.model_T, cell)
    with timer.stage("orientation"):
        orient = choose(reach, samples.tcp, samples.normal, samples.tangent, samples.extrude)
    with timer.stage("velocity"):
        q = orient.q
        T_tcp = kin.fk(q, reach.tool_m)
        tcp = T_tcp[:, :3, 3] * 1000.0
        axis = T_tcp[:, :3, 2]
        s = path_parameter(tcp, T_tcp[:, :3, :3])
        omega = angular_rates(T_tcp[:, :3, :3], s)
        dq = task_rates(q, tcp, axis, omega, s, reach.tool_m, cell.planning.damping)
    with timer.stage("timing"):
        vmax = np.radians(cell.robot.max_velocity_deg_s)
        amax = np.radians(cell.robot.max_acceleration_deg_s2)
        timing = time_law(q, dq, tcp, s, samples.speed, vmax, amax)
    with timer.stage("report"):
        alpha = np.degrees(alpha_of(axis, samples.tangent))
        traj = Trajectory(
            t=timing.t, q=q, qd=timing.qd, tcp=tcp, waypoint=samples.waypoint, alpha=alpha,
            extrude=samples.extrude, base_T=cell.robot.base_T, tool_T=cell.tool.tool_T,
            model_T=placement.model_T,
        )
        report = _report(toolpath, cell, reach, samples, orient, timing, placement, traj,
                         timer.seconds)
    status = "ok" if not report["unreachable"]["count"] else "unreachable waypoints"
    if timing.status != "ok":
        status = timing.status
    report["status"] = status
    return PlanResult(traj, report, samples, orient, timing, placement, orient.clearance,
                      status)


def _report(
    toolpath: Toolpath, cell: CellConfig, reach: Reach, samples: Samples, orient: Orientation,
    timing: Timing, placement: Placement, traj: Trajectory, seconds: dict[str, float],
) -> dict[str, Any]:
    """The "plan" section of report.json (mm, s, deg)."""
    ex = samples.extrude
    wp = samples.waypoint
    # unreachable toolpath waypoints with their reasons
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
    clear = orient.clearance
    has_c = np.isfinite(clear)
    k = int(np.nanargmin(np.where(has_c, clear, np.inf))) if has_c.any() else -1
    # speed: actual TCP speed on the step after each sample vs target
    dt = np.diff(traj.t)
    step = np.linalg.norm(np.diff(traj.tcp, axis=0), axis=1)
    v_step = step / np.maximum(dt, 1e-12)
    ex_step = ex[:-1] & (step > 1e-6)  # zero-length steps (repeated waypoints) have no speed
    target_step = samples.speed[:-1]
    ratio = v_step[ex_step] / np.maximum(target_step[ex_step], 1e-12)
    # over-deposition: constant extrusion C for longer than the toolpath speed asks
    C = cell.planning.extrusion_rate_mm3_s
    planned = step[ex_step] / np.maximum(target_step[ex_step], 1e-12)
    extra = np.maximum(dt[ex_step] - planned, 0.0) * C
    slowed = ratio < 0.95
    q_deg = np.degrees(traj.q)
    lo, hi = np.array(cell.robot.joint_min_deg), np.array(cell.robot.joint_max_deg)
    acc = np.abs(np.diff(traj.qd, axis=0)) / np.maximum(dt, 1e-12)[:, None]
    out: dict[str, Any] = {
        "waypoints": len(toolpath),
        "samples": len(traj),
        "duration_s": traj.duration_s,
        "placement": {"offset_mm": list(placement.offset_mm), "yaw_deg": placement.yaw_deg,
                      "evaluated": placement.evaluated,
                      "search_clearance_mm": placement.clearance_mm},
        "min_clearance_mm": float(clear[k]) if k >= 0 else None,
        "min_clearance_pair": names[orient.pair[k]] if k >= 0 and orient.pair[k] >= 0 else None,
        "min_clearance_time_s": float(traj.t[k]) if k >= 0 else None,
        "required_clearance_mm": cell.planning.clearance_mm,
        "alpha_deg": {**_stats(traj.alpha[ex]),
                      "tilted_samples": int(np.sum(np.abs(orient.tilt[ex]) > 1e-6)),
                      "tilt_max_deg": float(np.degrees(np.abs(orient.tilt).max()))},
        "joint_margin_deg": {
            "min_to_lower": list(np.round(q_deg.min(axis=0) - lo, 3)),
            "min_to_upper": list(np.round(hi - q_deg.max(axis=0), 3)),
        },
        "joint_velocity_peak_fraction": list(np.round(
            np.abs(traj.qd).max(axis=0) / np.radians(cell.robot.max_velocity_deg_s), 4)),
        "joint_acceleration_peak_fraction": list(np.round(
            acc.max(axis=0) / np.radians(cell.robot.max_acceleration_deg_s2), 4))
        if len(acc) else [0.0] * 6,
        "speed_ratio": {**_stats(ratio),
                        "within_5pct": float(np.mean(np.abs(ratio - 1) <= 0.05))
                        if len(ratio) else 1.0},
        "over_deposition": {
            "volume_mm3": float(extra.sum()),
            "fraction": float(extra.sum() / max(C * planned.sum(), 1e-12)),
            "slowed_steps": int(slowed.sum()),
            "max_local_factor": float(1.0 / max(ratio.min(), 1e-12)) if len(ratio) else 1.0,
        },
        "unreachable": {"count": int(bad.sum()), "by_reason": dict(Counter(reasons)),
                        "waypoints": detail},
        "time_law": {"status": timing.status, "iterations": timing.iterations},
        "timing_s": {k2: round(v, 4) for k2, v in seconds.items()},
    }
    return out
