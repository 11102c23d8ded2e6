"""Safe moves into and out of the gel: retract along the nozzle axis, transfer, plunge.

The nozzle may enter the gel only along its own line, so that only the shaft is ever below
the gel surface. A safe move from configuration ``q_from`` to ``q_to`` is therefore up to three
segments: a *retract* of the tip along the nozzle axis of ``q_from`` (constant orientation)
up to a safe height, a *transfer* by linear joint interpolation to the pose with the same
orientation as ``q_to`` whose tip lies on the nozzle axis of ``q_to`` at the safe height, and
a *plunge* along that axis down to ``q_to``. A pose already at or above the safe height needs
no retract (plunge). The planner uses it for the entry (home -> first sample) and the exit
(last sample -> home); the robot node for the approach of a resume sample.

Every sample is checked like the planner's samples (IK branch of home, joint limits with
margin, singularity, clearance to table, tank, gel and self), and the transfer samples also
keep the whole nozzle out of the gel. Samples are dense enough that no point of the robot
moves more than ``STEP_BOUND_MM`` between two of them (a point at most ``REACH_MM`` from a
joint axis moves at most ``REACH_MM * sum |dq|``), and each sample needs
``clearance_mm + STEP_BOUND_MM / 2``, so the clearance holds between the samples too.
Positions are mm, angles rad.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from core.tolerance import tol
from planner import kinematics as kin
from planner.collision import NOZZLE, segment_box_distance
from planner.reach import COLLISION, NO_IK, OK, REASONS, Reach
from planner.timing import Timing, path_parameter, time_law

REACH_MM = 1500.0  # farther than any robot or tool point lies from any joint axis
STEP_BOUND_MM = 2.0  # largest motion of any robot point between two checked samples
DOWN_MIN = 0.2  # the nozzle axis must point down at least this much (-z component)
RETRACT, TRANSFER, PLUNGE = 1, 2, 3
SEGMENT_NAMES = {RETRACT: "retract", TRANSFER: "transfer", PLUNGE: "plunge"}


@dataclass(frozen=True)
class SafeMove:
    """A checked safe move (see the module docstring).

    Attributes:
        q: (K, 6) float64, rad, from ``q_from`` to ``q_to`` (both included).
        tcp: (K, 3) float64, mm, nozzle tip in the base frame.
        segment: (K,) int8, RETRACT, TRANSFER or PLUNGE of each sample.
        stop: (K,) bool, the motion rests here (the ends and the corners between segments).
        status: (K,) int8, OK or the reason code (reach.REASONS) of each sample.
        clearance: (K,) float64, mm, smallest clearance of each sample.
        pair: (K,) int32, closest pair (into ``Reach.collision.names``), -1 if none; for a
            transfer sample whose nozzle is too close to the gel, the nozzle-gel pair.
        safe_z_mm: float, tip height of the transfer ends (base frame).
        reason: "" if every sample is OK, else one line naming the segment and the cause.
    """

    q: np.ndarray
    tcp: np.ndarray
    segment: np.ndarray
    stop: np.ndarray
    status: np.ndarray
    clearance: np.ndarray
    pair: np.ndarray
    safe_z_mm: float
    reason: str

    @property
    def ok(self) -> bool:
        return not self.reason


def tip_pose(reach: Reach, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tip position (3,) mm and orientation (3, 3) of configuration ``q`` (6,) rad."""
    T = kin.fk(np.asarray(q, dtype=float), reach.tool_m)
    return T[:3, 3] * 1000.0, T[:3, :3]


def axis_line(reach: Reach, q_end: np.ndarray, z_top_mm: float) -> np.ndarray:
    """Configurations (K, 6) rad along the nozzle axis of ``q_end``, from the tip height
    ``z_top_mm`` down to ``q_end`` (included; K = 1 if the tip is already that high).

    The orientation stays that of ``q_end``; rows are nan where there is no IK solution or
    the axis does not point down.
    """
    q_end = np.asarray(q_end, dtype=float)
    p, R = tip_pose(reach, q_end)
    a = R[:, 2]
    if p[2] >= z_top_mm - tol.slack:
        return q_end[None, :].copy()
    if a[2] > -DOWN_MIN:
        return np.vstack([np.full((1, 6), np.nan), q_end[None, :]])
    length = (z_top_mm - p[2]) / -a[2]
    step = min(reach.cell.planning.max_step_mm, STEP_BOUND_MM)
    for _ in range(3):  # refine until no robot point moves more than STEP_BOUND_MM
        n = max(int(np.ceil(length / step)), 1)
        f = np.linspace(1.0, 0.0, n + 1)
        tcp = p - f[:, None] * length * a
        q = reach.solve(tcp, np.broadcast_to(R, (n + 1, 3, 3)), q_end)
        q[-1] = q_end
        if np.isnan(q).any():  # out of reach somewhere on the line: no refinement helps
            break
        q = _unwrap_to(q, q_end)
        bound = float(np.nanmax(_step_bound(q))) if n > 0 else 0.0
        if not np.isfinite(bound) or bound <= STEP_BOUND_MM:
            break
        step *= STEP_BOUND_MM / bound * 0.9
    return q


def joint_segment(q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """Linear joint interpolation (K, 6) rad from ``q0`` to ``q1`` (both included), dense
    enough that no robot point moves more than STEP_BOUND_MM between two samples."""
    span = float(np.abs(np.asarray(q1) - np.asarray(q0)).sum())
    if not np.isfinite(span):  # an end without a solution: nothing to interpolate
        return np.vstack([q0, q1])
    n = max(int(np.ceil(span * REACH_MM / STEP_BOUND_MM)), 1)
    f = np.linspace(0.0, 1.0, n + 1)[:, None]
    return (1.0 - f) * q0 + f * q1


def _unwrap_to(q: np.ndarray, q_end: np.ndarray) -> np.ndarray:
    """Rows of ``q`` (K, 6) made continuous backwards from the last row (= ``q_end``)."""
    out = q.copy()
    has = ~np.isnan(q).any(axis=1)
    if has.sum() > 1:
        rev = out[has][::-1]
        out[np.flatnonzero(has)[::-1]] = np.unwrap(rev, axis=0)
    return out


def _step_bound(q: np.ndarray) -> np.ndarray:
    """Largest motion (K-1,) mm of any robot point on each step of ``q`` (K, 6) rad."""
    return REACH_MM * np.abs(np.diff(q, axis=0)).sum(axis=1)


def _gel_clearance(reach: Reach, q: np.ndarray) -> tuple[np.ndarray, int]:
    """Distance (S,) mm of the nozzle capsule to the gel volume, and the index of that pair
    (into ``reach.collision.names``, -1 if the cell names none)."""
    col = reach.collision
    names = [b.name for b in col.boxes]
    caps = [c.name for c in col.capsules]
    if "gel" not in names or NOZZLE not in caps:
        return np.full(len(q), np.inf), -1
    gel = col.boxes[names.index("gel")]
    ci = caps.index(NOZZLE)
    a, b = col.segments(q)
    d = segment_box_distance(a[:, ci], b[:, ci], gel) - col.capsules[ci].radius
    pair_name = f"{NOZZLE} vs gel"
    pair = col.names.index(pair_name) if pair_name in col.names else -1
    return d * 1000.0, pair


def check_move(reach: Reach, q: np.ndarray, segment: np.ndarray,
               tolerate_start: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Status (K,), clearance (K,) mm and closest pair (K,) of the samples of a move.

    Args:
        q: (K, 6) float64, rad (nan rows = no IK).
        segment: (K,) int8, RETRACT / TRANSFER / PLUNGE per sample.
        tolerate_start: the first samples may fail the clearance as long as they keep
            getting better (a retract from where the robot stands must be allowed to start).
    """
    ev = reach.check(q)
    status = ev.status.copy()
    clear = np.nan_to_num(ev.clearance, nan=-np.inf)
    pair = ev.pair.copy()
    bound = np.zeros(len(q))
    if len(q) > 1:
        b = np.nan_to_num(_step_bound(q), nan=np.inf)
        bound = 0.5 * np.maximum(np.r_[b, 0.0], np.r_[0.0, b])
    need = reach.cell.planning.clearance_mm + np.minimum(bound, STEP_BOUND_MM / 2)
    hit = clear < need
    has = ~np.isnan(q).any(axis=1)
    transfer = (segment == TRANSFER) & has
    if transfer.any():
        g, gp = _gel_clearance(reach, q[transfer])
        rows = np.flatnonzero(transfer)
        closer = g < clear[rows]
        clear[rows] = np.minimum(clear[rows], g)
        pair[rows[closer]] = gp
        hit[rows] = clear[rows] < need[rows]
    if tolerate_start and len(q) > 1:
        # a prefix whose clearance never decreases is what leaving the current pose costs
        nondec = np.r_[True, np.diff(clear) >= -tol.computed]
        prefix = np.logical_and.accumulate(nondec)
        hit &= ~prefix
    status[hit & (status == OK)] = COLLISION
    status[(status == COLLISION) & ~hit] = OK
    return status, clear, pair


def safe_move(reach: Reach, q_from: np.ndarray, q_to: np.ndarray, heights: Sequence[float],
              tolerate_start: bool = False) -> SafeMove:
    """The first safe move from ``q_from`` to ``q_to`` over the safe heights ``heights``
    (mm, tip z in the base frame, tried in order), or the last one tried with its reason."""
    best: SafeMove | None = None
    for z in heights:
        move = _safe_move_at(reach, np.asarray(q_from, float), np.asarray(q_to, float), float(z),
                             tolerate_start)
        if move.ok:
            return move
        best = best or move
    assert best is not None, "heights must not be empty"
    return best


def _safe_move_at(reach: Reach, q_from: np.ndarray, q_to: np.ndarray, z: float,
                  tolerate_start: bool) -> SafeMove:
    up = axis_line(reach, q_from, z)[::-1]  # q_from first, then up its axis
    down = axis_line(reach, q_to, z)  # down its axis, q_to last
    parts: list[np.ndarray] = []
    segs: list[np.ndarray] = []
    if len(up) > 1:
        parts.append(up)
        segs.append(np.full(len(up), RETRACT, np.int8))
    a, b = up[-1], down[0]
    if np.isnan(a).any() or np.isnan(b).any():
        mid = np.vstack([a, b])
    else:
        mid = joint_segment(a, b)
    if len(mid) > 1 and not np.abs(mid[-1] - mid[0]).max() <= tol.slack:  # (nan: keep)
        parts.append(mid[1:] if parts else mid)
        segs.append(np.full(len(parts[-1]), TRANSFER, np.int8))
    if len(down) > 1:
        parts.append(down[1:] if parts else down)
        segs.append(np.full(len(parts[-1]), PLUNGE, np.int8))
    if not parts:
        parts, segs = [q_from[None, :]], [np.full(1, TRANSFER, np.int8)]
    q = np.vstack(parts)
    segment = np.concatenate(segs)
    K = len(q)
    stop = np.zeros(K, dtype=bool)
    stop[0] = stop[-1] = True
    stop[:-1] |= segment[1:] != segment[:-1]  # rest at the corner (last of a segment)
    has = ~np.isnan(q).any(axis=1)
    tcp = np.full((K, 3), np.nan)
    if has.any():
        tcp[has] = kin.fk(q[has], reach.tool_m)[:, :3, 3] * 1000.0
    status, clear, pair = check_move(reach, q, segment, tolerate_start)
    if K == 1:  # no motion: nothing to check beyond the pose itself
        status[:] = OK
    reason = ""
    bad = np.flatnonzero(status != OK)
    if len(bad):
        i = int(bad[0])
        why = REASONS[int(status[i])]
        if status[i] == NO_IK and segment[i] != TRANSFER:
            _, R = tip_pose(reach, q_to if segment[i] == PLUNGE else q_from)
            if R[2, 2] > -DOWN_MIN:
                why = "the nozzle axis does not point down"
        if status[i] == COLLISION and pair[i] >= 0:
            why += f" ({reach.collision.names[pair[i]]})"
        reason = f"{SEGMENT_NAMES[int(segment[i])]} at tip height {z:.0f} mm: {why}"
    return SafeMove(q, tcp, segment, stop, status, clear, pair, z, reason)


def safe_heights(reach: Reach) -> list[float]:
    """Tip heights (mm, base frame) to try for transfers, lowest first (the shortest
    plunge): ``approach_above_gel_mm`` above the gel surface, halfway up, and the home pose's
    tip height (a pose can be out of reach that high, or blocked that low)."""
    home_z = float(tip_pose(reach, reach.home)[0][2])
    cell = reach.cell
    tank = np.linalg.inv(cell.robot.base_T) @ cell.tank.floor_T
    gel_z = float(tank[2, 3] + cell.tank.gel_fill_mm)
    low = gel_z + cell.planning.approach_above_gel_mm
    return [home_z] if low >= home_z else [low, 0.5 * (low + home_z), home_z]


def move_speed(reach: Reach, segment: np.ndarray) -> np.ndarray:
    """TCP speed cap (K,) mm/s per sample: the travel speed along the nozzle axis (in and
    near the gel), the transfer speed above it (the joint limits usually bind first)."""
    planning = reach.cell.planning
    return np.where(segment == TRANSFER, planning.transfer_speed_mm_s,
                    planning.travel_speed_mm_s)


def time_move(reach: Reach, move: SafeMove) -> Timing:
    """Time law of a move within the joint limits at the ``move_speed`` caps, at rest at
    both ends and at its corners (``move.stop``)."""
    q, stop = move.q, move.stop
    T = kin.fk(q, reach.tool_m)
    tcp = T[:, :3, 3] * 1000.0
    keep = np.ones(len(q), dtype=bool)
    keep[1:] = np.abs(np.diff(q, axis=0)).max(axis=1) > tol.slack
    qk = q[keep]
    if len(qk) < 2:
        z = np.zeros(len(q))
        return Timing(np.arange(len(q)) * tol.still, np.zeros((len(q), 6)), z, z,
                      np.zeros(len(q), bool), 0, "ok")
    s = path_parameter(tcp[keep], T[keep, :3, :3])
    dq = np.gradient(qk, s, axis=0)
    vmax = np.radians(reach.cell.robot.max_velocity_deg_s)
    amax = np.radians(reach.cell.robot.max_acceleration_deg_s2)
    target = move_speed(reach, move.segment)[keep]
    timing = time_law(qk, dq, tcp[keep], s, target, vmax, amax, stop=stop[keep])
    if keep.all():
        return timing
    src = np.cumsum(keep) - 1
    t = timing.t[src] + tol.still * np.cumsum(~keep)
    return Timing(t, timing.qd[src], timing.speed[src], timing.target[src],
                  timing.limited[src], timing.iterations, timing.status)
