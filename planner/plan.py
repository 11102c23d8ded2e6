"""Toolpath -> timed UR5e joint trajectory: the ``mesp plan`` pipeline as a library call.

Stages: normals (repair single-waypoint normal spikes), placement (search the model's place in
the tank), resample (insert samples on long segments), upright (turn printing directions
towards vertical where the wrist would near the base axis), orientation (spin and alpha per
sample), continuity (insert samples where a step in joint space would swing the tip off the
path), entry (into and out of the gel along the nozzle axis), velocity (DLS joint rates),
timing (time law within joint limits), report, verify (the executed trajectory against every
limit: ``planner.verify``; the status is ok only if all hold). Where the plan is not ok at the
searched placement (a blocked entry or exit, a waypoint the search's sample missed, a broken
limit), the stages after it run again at the search's next placements (another yaw first:
where the job starts and ends decides). ``plan`` returns the ``Trajectory`` stage, the report
section and the status with its one-line message (``planner.status``).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy import ndimage

from planner import kinematics as kin
from planner.cell import CellConfig
from planner.continuity import SWING_TOL_MM, subdivide
from planner.entry import (
    TRANSFER,
    SafeMove,
    joint_segment,
    move_speed,
    safe_heights,
    safe_move,
)
from planner.orientation import (
    ALPHA,
    ALPHA_MIN_STEP_MM,
    COLLISION,
    OK,
    REASONS,
    Orientation,
    Reach,
    alpha_allowed,
    alpha_of,
    choose,
    unit,
)
from planner.path_smoothing import smooth_along_paths
from planner.placement import (
    Placement,
    bbox,
    choose_placement,
    fit_gel,
    model_transform,
    waypoint_tangents,
)
from planner.refusal import cause_of
from planner.status import CAUSES, MESSAGES, Cause, PlanStatus
from planner.timing import (  # noqa: F401  (path_parameter: re-exported)
    ROTATION_MM_PER_RAD,
    Timing,
    angular_rates,
    path_parameter,
    task_rates,
    time_law,
)
from planner.trajectory import Trajectory
from planner.upright import COMFORT, Upright, turn_towards, upright
from planner.verify import verify
from slicer.errors import InputError
from slicer.progress import Progress, StageTimer
from slicer.stages import Toolpath


@dataclass(frozen=True)
class Samples:
    """The toolpath resampled in the robot base frame.

    Attributes:
        tcp: (M, 3) float64, mm, target nozzle tip positions.
        normal: (M, 3) float64, unit printing directions.
        tangent: (M, 3) float64, unit motion directions: of the step leaving the sample where
            it deposits, of the step arriving where only that one deposits.
        waypoint: (M,) int32, toolpath index, -1 for inserted samples.
        extrude: (M,) bool, deposit on the step to the next sample.
        speed: (M,) float64, mm/s, target TCP speed.
        height: (M,) float64, mm, layer height (for over-deposition).
        arrive: (M, 3) float64, unit direction of the step arriving at the sample where that
            step deposits, zero rows elsewhere. A filament is laid along each depositing step
            with the nozzle of both its ends, so alpha is checked against both directions.
    """

    tcp: np.ndarray
    normal: np.ndarray
    tangent: np.ndarray
    waypoint: np.ndarray
    extrude: np.ndarray
    speed: np.ndarray
    height: np.ndarray
    arrive: np.ndarray


@dataclass(frozen=True)
class PlanResult:
    """Everything ``plan`` produced.

    Attributes:
        trajectory: the stage written to trajectory.npz.
        report: the "plan" section of report.json.
        samples, orientation, timing, placement: intermediate values (for plots and tests).
        clearance: (M,) float64, mm, clearance along the trajectory (nan where not sampled).
        status: ``PlanStatus.OK`` or the first limit not kept (only OK may be executed).
        message: one line: what holds, or which waypoint/sample breaks what and why.
        cause: why the first refused waypoint is refused, in the user's terms (None if none).
    """

    trajectory: Trajectory
    report: dict[str, Any]
    samples: Samples
    orientation: Orientation
    timing: Timing
    placement: Placement
    clearance: np.ndarray
    status: PlanStatus
    message: str
    cause: Cause | None = None


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
                       np.full(1, planning.travel_speed_mm_s), toolpath.height.copy(),
                       np.zeros((1, 3)))
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
    # alpha is a property of the filament laid down: a waypoint's direction is that of the
    # depositing segment leaving it, else of the one arriving, else (a move) its path's
    seg_live = seg_extrude & (length > ALPHA_MIN_STEP_MM)
    ext_in = np.r_[False, seg_live]
    ext_out = np.r_[seg_live, False]
    T = T.copy()
    out = np.flatnonzero(ext_out)
    T[out] = seg_dir[out]
    stops = np.flatnonzero(ext_in & ~ext_out)
    T[stops] = seg_dir[stops - 1]
    arrive_wp = np.zeros((N, 3))
    arr = np.flatnonzero(ext_in)
    arrive_wp[arr] = seg_dir[arr - 1]
    # inserted samples move along their segment
    tangent = np.where((k == 0)[:, None], T[seg_of], seg_dir[seg_of])
    tangent = np.concatenate([tangent, T[-1:]])
    bad = np.linalg.norm(tangent, axis=1) < 0.5
    tangent[bad] = np.concatenate([seg_dir, seg_dir[-1:]])[np.minimum(
        np.concatenate([seg_of, [N - 2]])[bad], N - 2)]
    inserted_live = (k > 0) & seg_live[seg_of]
    arrive = np.where((k == 0)[:, None], arrive_wp[seg_of],
                      np.where(inserted_live[:, None], seg_dir[seg_of], 0.0))
    arrive = np.concatenate([arrive, arrive_wp[-1:]])
    waypoint = np.concatenate([np.where(k == 0, seg_of, -1), [N - 1]]).astype(np.int32)
    extrude = np.concatenate([seg_extrude[seg_of], [False]])
    # a waypoint sample keeps its own toolpath speed, also where the next segment is a move
    # between paths: the last step of a path deposits at the path's speed (the travel speed
    # there would make the time law accelerate on that extruding step); samples inserted on
    # a move between paths take the travel speed
    own = np.where(v > 0, v, planning.travel_speed_mm_s)
    speed = np.concatenate([np.where(k == 0, own[seg_of], seg_v0[seg_of] * (1 - f)
                                     + seg_v1[seg_of] * f), own[-1:]])
    h = toolpath.height
    height = np.concatenate([h[seg_of] * (1 - f) + h[seg_of + 1] * f, h[-1:]])
    return Samples(tcp, normal, tangent, waypoint, extrude, speed, height, arrive)


def repair_normals(toolpath: Toolpath, spike_deg: float = 20.0,
                   agree_deg: float = 10.0) -> tuple[Toolpath, np.ndarray]:
    """Replace isolated normal spikes (one or two waypoints) by their neighbours' mean.

    A waypoint's normal is a spike when it deviates more than ``spike_deg`` from the mean of
    the normals ``gap`` waypoints before and after it (gap 1, then 2, within one path) while
    those two agree within ``agree_deg``. The slicer occasionally yields such spikes (a
    degenerate layer triangle); following one would swing the wrist tens of degrees within
    a fraction of a millimetre of path. Returns the repaired toolpath and the (N,) bool mask
    of repaired waypoints.
    """
    n = np.array(toolpath.normal, dtype=float)
    path = toolpath.path
    N = len(n)
    done = np.zeros(N, dtype=bool)
    for gap in (1, 2):
        if N <= 2 * gap:
            break
        i = np.arange(gap, N - gap)
        prv, nxt = i - gap, i + gap
        same = (path[prv] == path[i]) & (path[nxt] == path[i])
        m = unit(n[prv] + n[nxt])
        agree = np.einsum("ij,ij->i", n[prv], n[nxt]) >= np.cos(np.radians(agree_deg))
        spike = np.einsum("ij,ij->i", n[i], m) < np.cos(np.radians(spike_deg))
        fix = i[same & agree & spike]
        n[fix] = m[same & agree & spike]
        done[fix] = True
    if not done.any():
        return toolpath, done
    return replace(toolpath, normal=n), done


TURN_DEG_PER_MM = 1.5  # normals turning faster than this along a path are smoothed


def smooth_normals(toolpath: Toolpath, k: int, max_deg: float) -> tuple[Toolpath, np.ndarray]:
    """Normals averaged over +-``k`` waypoints of their path, moved at most ``max_deg``.

    Where the normal turns sharply along a path, following it exactly makes the long tool
    swing the arm and forces the TCP slower than the toolpath speed; a small, bounded
    deviation from -normal (it changes alpha by at most ``max_deg``) keeps the speed.
    Returns the smoothed toolpath and the (N,) deviation in rad.
    """
    n = np.asarray(toolpath.normal, dtype=float)
    N = len(n)
    if k <= 0 or max_deg <= 0 or N < 3:
        return toolpath, np.zeros(N)
    path = toolpath.path
    idx = np.arange(N)
    new = np.r_[True, path[1:] != path[:-1]]
    first = np.maximum.accumulate(np.where(new, idx, 0))
    last_rev = np.minimum.accumulate(np.where(np.r_[path[1:] != path[:-1], True], idx,
                                              N - 1)[::-1])[::-1]
    lo = np.maximum(idx - k, first)
    hi = np.minimum(idx + k, last_rev)
    S = np.concatenate([np.zeros((1, 3)), np.cumsum(n, axis=0)])
    m = unit((S[hi + 1] - S[lo]) / (hi - lo + 1)[:, None])
    out = turn_towards(n, m, np.radians(max_deg))  # towards the mean, at most the cap
    # only where the normal turns fast (faster than TURN_DEG_PER_MM over the window, or over
    # one step: a spike at one waypoint, e.g. where a layer curls at its edge, turns away
    # and back, so the window's ends agree)
    P = toolpath.position
    rate = np.radians(TURN_DEG_PER_MM)
    span = np.linalg.norm(P[hi] - P[lo], axis=1)
    turn = np.arccos(np.clip(np.einsum("ij,ij->i", n[hi], n[lo]), -1.0, 1.0))
    fast = turn > rate * np.maximum(span, 1e-9)
    step_turn = np.arccos(np.clip(np.einsum("ij,ij->i", n[1:], n[:-1]), -1.0, 1.0))
    step_len = np.linalg.norm(P[1:] - P[:-1], axis=1)
    sharp = (step_turn > rate * np.maximum(step_len, 1e-9)) & ~new[1:]
    fast[1:] |= sharp
    fast[:-1] |= sharp
    fast = ndimage.binary_dilation(fast, structure=np.ones(2 * k + 1, dtype=bool))
    out = np.where(fast[:, None], out, n)
    dev = np.where(fast, np.arccos(np.clip(np.einsum("ij,ij->i", out, n), -1.0, 1.0)), 0.0)
    return replace(toolpath, normal=out), dev


REPEAT_DT_S = 1e-6  # time step given to a sample that repeats the previous pose


def moving_samples(q: np.ndarray) -> np.ndarray:
    """(M,) bool: False for samples whose joints equal the previous sample's (to 1e-6 rad)."""
    keep = np.ones(len(q), dtype=bool)
    if len(q) > 1:
        keep[1:] = np.abs(np.diff(q, axis=0)).max(axis=1) > 1e-6
    return keep


def expand_timing(timing: Timing, keep: np.ndarray) -> Timing:
    """The time law of the moving samples (``keep``) spread back over all samples.

    A repeated sample takes the values of the sample it repeats, REPEAT_DT_S later (``t``
    must increase), so every step between moving samples keeps its duration.
    """
    if keep.all():
        return timing
    src = np.cumsum(keep) - 1
    t = timing.t[src] + REPEAT_DT_S * np.cumsum(~keep)
    return Timing(t, timing.qd[src], timing.speed[src], timing.target[src],
                  timing.limited[src], timing.iterations, timing.status)


def _stats(x: np.ndarray) -> dict[str, float]:
    if not len(x):
        return {}
    p = np.percentile(x, [5, 50, 95])
    return {"min": float(x.min()), "p5": float(p[0]), "p50": float(p[1]),
            "p95": float(p[2]), "max": float(x.max()), "mean": float(x.mean())}


REPLANS = 4  # placements tried after the best one where its entry or exit is blocked


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
    cell = fit_gel(cell, toolpath)
    reach = Reach(cell)
    with timer.stage("normals"):
        toolpath, repaired = repair_normals(toolpath)
        toolpath, smoothed = smooth_along_paths(toolpath, cell.planning.smooth_length_mm,
                                                cell.planning.smooth_max_deg)
    with timer.stage("placement"):
        searched = placement is None
        if placement is None:
            placement = choose_placement(reach, toolpath)
    result = _plan_placed(toolpath, reach, placement, timer, repaired, smoothed)
    if searched and _refused(result):
        # the entry or exit depends on where the job starts and ends, and the placement score
        # checks only a sample of the waypoints (a lone one at a steep edge can be out of
        # reach, a sample between them near a wall): re-plan at the search's other reaching
        # placements
        box = bbox(toolpath)
        tries = 0
        for x, y, yaw, clear in placement.alternatives[:REPLANS]:
            tries += 1
            offset = (x, y, cell.placement.offset_mm[2])
            alt = replace(placement, model_T=model_transform(cell, box, np.array(offset), yaw),
                          offset_mm=offset, yaw_deg=yaw, clearance_mm=clear)
            again = _plan_placed(toolpath, reach, alt, timer, repaired, smoothed,
                                 f" (yaw {yaw:g})")
            again.report["placement"]["replanned"] = tries
            if not _refused(again):
                return again
        result.report["placement"]["replanned"] = tries
    return result


def _refused(result: PlanResult) -> bool:
    """The plan is not executable at its placement (any status but ok: an unreachable
    waypoint, a blocked entry or exit, a limit the verification found broken)."""
    return result.status != PlanStatus.OK


def _plan_placed(toolpath: Toolpath, reach: Reach, placement: Placement, timer: StageTimer,
                 repaired: np.ndarray, smoothed: np.ndarray, tag: str = "") -> PlanResult:
    """The stages after the placement (module docstring), for one placement; ``tag`` follows
    the stage names (a re-plan's stages are told apart from the first plan's)."""
    cell = reach.cell
    with timer.stage("resample" + tag):
        samples = resample(toolpath, placement.model_T, cell)
    with timer.stage("upright" + tag):
        up = upright(reach, samples.tcp, samples.normal, samples.tangent, samples.extrude,
                     samples.arrive)
    with timer.stage("orientation" + tag):
        orient = choose(reach, samples.tcp, up.normal, samples.tangent, samples.extrude,
                        arrive=samples.arrive)
    with timer.stage("continuity" + tag):
        samples, orient, split = _continuous(reach, samples, orient)
    with timer.stage("entry" + tag):
        # home -> above the first sample -> plunge along its nozzle axis; the mirror at the end
        heights = safe_heights(reach)
        entry = safe_move(reach, reach.home, orient.q[0], heights)
        leave = safe_move(reach, orient.q[-1], reach.home, heights)
        samples, orient, part, corner = _with_moves(reach, samples, orient, entry, leave)
    with timer.stage("velocity" + tag):
        q = orient.q
        T_tcp = kin.fk(q, reach.tool_m)
        tcp = T_tcp[:, :3, 3] * 1000.0
        axis = T_tcp[:, :3, 2]
        # samples that repeat the previous pose (repeated waypoints) carry no motion: time
        # and joint rates come from the others, the repeats follow 1 us later
        keep = moving_samples(q)
        s = path_parameter(tcp[keep], T_tcp[keep, :3, :3])
        # entry and exit: joint rates of the sampled joint path; the toolpath: DLS rates
        dq = np.gradient(q[keep], s, axis=0)
        main = part[keep] == 1
        omega = angular_rates(T_tcp[keep][main, :3, :3], s[main])
        dq[main] = task_rates(q[keep][main], tcp[keep][main], axis[keep][main], omega, s[main],
                              reach.tool_m, cell.planning.damping)
        # at rest where the toolpath begins and ends and at the corners of entry and exit
        stop = np.zeros(len(q), dtype=bool)
        stop[np.flatnonzero(part == 1)[[0, -1]]] = True
        stop |= corner
    with timer.stage("timing" + tag):
        vmax = np.radians(cell.robot.max_velocity_deg_s)
        amax = np.radians(cell.robot.max_acceleration_deg_s2)
        timing = expand_timing(
            time_law(q[keep], dq, tcp[keep], s, samples.speed[keep], vmax, amax,
                     stop=stop[keep]), keep)
    with timer.stage("report" + tag):
        alpha = np.degrees(alpha_of(axis, samples.tangent))
        traj = Trajectory(
            t=timing.t, q=q, qd=timing.qd, tcp=tcp, waypoint=samples.waypoint, alpha=alpha,
            extrude=samples.extrude, base_T=cell.robot.base_T, tool_T=cell.tool.tool_T,
            model_T=placement.model_T,
        )
        report = _report(toolpath, cell, reach, samples, orient, timing, placement, traj,
                         timer.seconds)
        report["normals_repaired"] = int(repaired.sum())
        report["normals_smoothed_deg"] = _stats(np.degrees(smoothed))
        report["gel_fill_mm"] = cell.tank.gel_fill_mm
        report["continuity"] = split
        report["upright"] = _upright_report(up, orient, part == 1)
        report["entry"] = _move_report(entry, traj, part == 0)
        report["exit"] = _move_report(leave, traj, part == 2)
    un = report["unreachable"]
    # entry and exit samples are reported under "entry"/"exit", not as between-waypoint ones
    between = np.flatnonzero((orient.status != OK) & (samples.waypoint < 0) & (part == 1))
    un["between_waypoints"] = int(between.size)
    status, message = PlanStatus.OK, MESSAGES[PlanStatus.OK]
    cause: Cause | None = None
    if un["count"]:
        status = PlanStatus.UNREACHABLE
        message, cause = _unreachable_message(toolpath, reach, samples, orient, part)
    elif between.size:
        status = PlanStatus.UNREACHABLE_BETWEEN
        message = _between_status(reach, samples, orient, between)
    for move, blocked in ((entry, PlanStatus.ENTRY_BLOCKED), (leave, PlanStatus.EXIT_BLOCKED)):
        if not move.ok and status == PlanStatus.OK:
            status = blocked
            message = (f"{blocked}: {move.reason}; move the part away from the walls "
                       "(placement) or change the home pose")
    if split["worst_swing_mm"] > SWING_TOL_MM and status == PlanStatus.OK:
        status = PlanStatus.SWING
        message = (f"the nozzle would leave the path by {split['worst_swing_mm']:.2f} mm between "
                   "two samples (a pose next to a singularity); move the part (placement) or "
                   "the robot base")
    if timing.status != "ok" and status == PlanStatus.OK:
        status, message = PlanStatus.TIME_LAW, timing.status
    with timer.stage("verify" + tag):
        # whatever the stages decided: the executed trajectory against every limit
        checked = verify(traj, samples.speed, reach)
    report["verified"] = checked.as_report()
    if checked.breaches and status == PlanStatus.OK:
        b = checked.breaches[0]
        status = b.status
        layer = (f" (layer {int(toolpath.layer[b.waypoint])})" if b.waypoint >= 0 else "")
        message = (f"{MESSAGES[b.status]}: {b.count} samples, the first after waypoint "
                   f"{b.waypoint}{layer}, worst {b.detail}")
    report["status"] = str(status)
    report["message"] = message
    report["cause"] = None if cause is None else str(cause)
    return PlanResult(traj, report, samples, orient, timing, placement, orient.clearance,
                      status, message, cause)


def _unreachable_message(toolpath: Toolpath, reach: Reach, samples: Samples,
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


def _upright_report(up: Upright, orient: Orientation, main: np.ndarray) -> dict[str, Any]:
    """How many samples were turned towards vertical, how far, and the singularity margins
    on the layer normals and along the planned motion (``main``: (M,) bool, the toolpath's
    samples, without entry and exit)."""
    margin = kin.singularity_margin(orient.q[main])
    return {"samples": int(np.sum(up.angle > 1e-9)),
            "max_deg": round(float(np.degrees(up.angle.max())), 3) if len(up.angle) else 0.0,
            "comfort_margin": COMFORT,
            "margin_on_normal_min": round(float(up.margin.min()), 4) if len(up.margin) else 1.0,
            "margin_min": round(float(np.nanmin(margin)), 4) if margin.size else 1.0}


def _between_status(reach: Reach, samples: Samples, orient: Orientation,
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


def _continuous(reach: Reach, samples: Samples, orient: Orientation
                ) -> tuple[Samples, Orientation, dict[str, Any]]:
    """Samples inserted where the joint-space step between two samples would swing the tip
    off the path (``continuity.subdivide``), checked like the others; and the report."""
    sub = subdivide(orient.q, reach.solve, reach.tool_m)
    report: dict[str, Any] = {"tolerance_mm": SWING_TOL_MM,
                              "steps_split": int(np.unique(sub.step).size),
                              "samples_inserted": len(sub.step),
                              "worst_swing_mm": round(sub.worst_mm, 4)}
    if len(sub.step) == 0:
        return samples, orient, report
    k, f = sub.step, sub.fraction
    at = k + 1  # np.insert keeps the order of equal positions: sorted by (step, fraction)

    def between(a: np.ndarray) -> np.ndarray:
        w = f.reshape((-1,) + (1,) * (a.ndim - 1))
        return (1.0 - w) * a[k] + w * a[k + 1]

    T = kin.fk(sub.q, reach.tool_m)
    ev = reach.check(sub.q)
    # an inserted sample moves along its step's chord, and its alpha is checked against it
    step = samples.tcp[k + 1] - samples.tcp[k]
    long_step = np.linalg.norm(step, axis=1) > ALPHA_MIN_STEP_MM
    chord = np.where(long_step[:, None], unit(step), samples.tangent[k])
    status = ev.status.copy()
    extrude = samples.extrude[k] & long_step
    off = ~alpha_allowed(reach.cell, alpha_of(T[:, :3, 2], chord), extrude)
    status[off & (status == OK)] = ALPHA
    new_samples = Samples(
        tcp=np.insert(samples.tcp, at, between(samples.tcp), axis=0),
        normal=np.insert(samples.normal, at, unit(between(samples.normal)), axis=0),
        tangent=np.insert(samples.tangent, at, chord, axis=0),
        waypoint=np.insert(samples.waypoint, at, -1),
        extrude=np.insert(samples.extrude, at, samples.extrude[k]),
        speed=np.insert(samples.speed, at, between(samples.speed)),
        height=np.insert(samples.height, at, between(samples.height)),
        arrive=np.insert(samples.arrive, at, np.where(extrude[:, None], chord, 0.0), axis=0),
    )
    o = orient
    new_orient = Orientation(
        q=np.insert(o.q, at, sub.q, axis=0), axis=np.insert(o.axis, at, T[:, :3, 2], axis=0),
        psi=np.insert(o.psi, at, between(o.psi)), tilt=np.insert(o.tilt, at, between(o.tilt)),
        lean=np.insert(o.lean, at, between(o.lean)),
        status=np.insert(o.status, at, status).astype(np.int8),
        pair=np.insert(o.pair, at, ev.pair).astype(np.int32),
        clearance=np.insert(o.clearance, at, ev.clearance),
    )
    return new_samples, new_orient, report


def _with_moves(reach: Reach, samples: Samples, orient: Orientation, entry: SafeMove,
                leave: SafeMove) -> tuple[Samples, Orientation, np.ndarray, np.ndarray]:
    """Samples and orientation with the entry before and the exit after the toolpath's.

    Returns them, ``part`` (M,) int8: 0 entry, 1 toolpath, 2 exit, and ``corner`` (M,) bool:
    the entry's and exit's rest samples (``SafeMove.stop``). An entry or exit
    without a solution somewhere is replaced by the plain joint interpolation (so the arrays
    stay finite) and keeps its failing status.
    """
    moves = []
    for move, first in ((entry, True), (leave, False)):
        q, status, stop = move.q, move.status, move.stop
        if np.isnan(q).any():
            q = joint_segment(move.q[0] if first else orient.q[-1],
                              orient.q[0] if first else move.q[-1])
            status = np.full(len(q), int(move.status[move.status != OK][0]), np.int8)
            clear, pair = np.full(len(q), np.nan), np.full(len(q), -1, np.int32)
            stop = np.zeros(len(q), dtype=bool)
            stop[[0, -1]] = True
        else:
            clear, pair = move.clearance, move.pair
        sl = slice(0, -1) if first else slice(1, None)  # the shared toolpath sample once
        seg = move.segment if len(move.segment) == len(q) else np.full(len(q), TRANSFER)
        v = move_speed(reach, seg)
        moves.append((q[sl], status[sl], clear[sl], pair[sl], stop[sl], v[sl]))
    (qa, sa, ca, pa, ka, va), (qb, sb, cb, pb, kb, vb) = moves
    T = kin.fk(np.vstack([qa, qb]), reach.tool_m)
    tcp = T[:, :3, 3] * 1000.0
    axis = T[:, :3, 2]
    na = len(qa)

    def cat(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
        return np.concatenate([a, b, c])

    M = len(samples.tcp)
    tcp_all = cat(tcp[:na], samples.tcp, tcp[na:])
    tangent = unit(np.gradient(tcp_all, axis=0)) if len(tcp_all) > 1 else np.zeros_like(tcp_all)
    tangent[na:na + M] = samples.tangent
    n_a, n_b = na, len(qb)
    new_samples = Samples(
        tcp=tcp_all,
        normal=cat(-axis[:na], samples.normal, -axis[na:]),
        tangent=tangent,
        waypoint=cat(np.full(n_a, -1, np.int32), samples.waypoint, np.full(n_b, -1, np.int32)),
        extrude=cat(np.zeros(n_a, bool), samples.extrude, np.zeros(n_b, bool)),
        speed=cat(va, samples.speed, vb),
        height=cat(np.full(n_a, samples.height[0]), samples.height,
                   np.full(n_b, samples.height[-1])),
        arrive=cat(np.zeros((n_a, 3)), samples.arrive, np.zeros((n_b, 3))),
    )
    o = orient
    new_orient = Orientation(
        q=cat(qa, o.q, qb), axis=cat(axis[:na], o.axis, axis[na:]),
        psi=cat(np.full(n_a, o.psi[0]), o.psi, np.full(n_b, o.psi[-1])),
        tilt=cat(np.zeros(n_a), o.tilt, np.zeros(n_b)),
        lean=cat(np.zeros(n_a), o.lean, np.zeros(n_b)),
        status=cat(sa, o.status, sb).astype(np.int8), pair=cat(pa, o.pair, pb).astype(np.int32),
        clearance=cat(ca, o.clearance, cb),
    )
    part = cat(np.zeros(n_a, np.int8), np.ones(M, np.int8), np.full(n_b, 2, np.int8))
    return new_samples, new_orient, part, cat(ka, np.zeros(M, bool), kb)


def _move_report(move: SafeMove, traj: Trajectory, rows: np.ndarray) -> dict[str, Any]:
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


def _report(
    toolpath: Toolpath, cell: CellConfig, reach: Reach, samples: Samples, orient: Orientation,
    timing: Timing, placement: Placement, traj: Trajectory, seconds: dict[str, float],
) -> dict[str, Any]:
    """The "plan" section of report.json (mm, s, deg)."""
    ex = samples.extrude
    wp = samples.waypoint
    traj_axis = orient.axis
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
    # the toolpath speed varies linearly along a segment (resample), so a step's target is
    # the mean of its ends' speeds
    target_step = 0.5 * (samples.speed[:-1] + samples.speed[1:])
    ratio = v_step[ex_step] / np.maximum(target_step[ex_step], 1e-12)
    # over-deposition: constant extrusion C for longer than the toolpath speed asks; C is the
    # job's (its profile's, through eq. 4: W H v = C at every extruding waypoint)
    C = float(np.median((toolpath.width * toolpath.height * toolpath.speed)[toolpath.extrude])
              ) if toolpath.extrude.any() else 0.0
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
                      "checked_waypoints": placement.checked,
                      "waypoints_needing_tilt": placement.need_tilt,
                      "search_clearance_mm": placement.clearance_mm},
        "min_clearance_mm": float(clear[k]) if k >= 0 else None,
        "min_clearance_pair": names[orient.pair[k]] if k >= 0 and orient.pair[k] >= 0 else None,
        "min_clearance_time_s": float(traj.t[k]) if k >= 0 else None,
        "required_clearance_mm": cell.planning.clearance_mm,
        "alpha_deg": {**_stats(traj.alpha[ex]),
                      "tilted_samples": int(np.sum(np.abs(orient.tilt[ex]) > 1e-6)),
                      "tilt_max_deg": float(np.degrees(np.abs(orient.tilt).max()))},
        "lean_deg": {**_stats(np.degrees(orient.lean[ex])),
                     "leaned_samples": int(np.sum(np.abs(orient.lean[ex]) > 1e-6)),
                     "lean_max_deg": float(np.degrees(np.abs(orient.lean).max())),
                     "limit_deg": cell.planning.lean_max_deg},
        "deviation_deg": _stats(np.degrees(np.arccos(np.clip(
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
        "speed_ratio": {**_stats(ratio),
                        "within_5pct": float(np.mean(np.abs(ratio - 1) <= 0.05))
                        if len(ratio) else 1.0,
                        # the same by extruded length (short steps at a turn weigh less)
                        "within_5pct_length": float(
                            np.sum(step[ex_step] * (np.abs(ratio - 1) <= 0.05))
                            / max(float(step[ex_step].sum()), 1e-12)) if len(ratio) else 1.0},
        "over_deposition": {
            "volume_mm3": float(extra.sum()),
            "fraction": float(extra.sum() / max(C * planned.sum(), 1e-12)),
            "slowed_steps": int(slowed.sum()),
            "max_local_factor": float(1.0 / max(ratio.min(), 1e-12)) if len(ratio) else 1.0,
        },
        "unreachable": {"count": int(bad.sum()), "by_reason": dict(Counter(reasons)),
                        "waypoints": detail,
                        # samples inserted between waypoints (long moves) that fail too
                        "between_waypoints": int(((orient.status != OK) & (wp < 0)).sum())},
        "time_law": {"status": timing.status, "iterations": timing.iterations},
        "timing_s": {k2: round(v, 4) for k2, v in seconds.items()},
    }
    return out
