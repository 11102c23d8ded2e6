"""The toolpath as samples of the planned motion, in the robot base frame.

``resample`` maps the waypoints into the base frame and inserts samples so no step exceeds
``max_step_mm``; ``insert_between`` adds the samples the continuity check asks for and
``with_moves`` joins the entry and exit moves; ``moving_samples``/``expand_timing`` let a
sample that repeats the previous pose take no time. Every function returns new values (the
stages are immutable).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.stages import Toolpath
from core.tolerance import tol
from planner import kinematics as kin
from planner.cell import CellConfig
from planner.continuity import Subdivision
from planner.entry import TRANSFER, SafeMove, joint_segment, move_speed
from planner.nozzle_axis import ALPHA_MIN_STEP_MM, alpha_allowed, alpha_of, unit
from planner.orientation import Orientation
from planner.reach import ALPHA, OK, Reach
from planner.timing import Timing


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



def waypoint_tangents(position: np.ndarray, path: np.ndarray) -> np.ndarray:
    """Unit motion direction (N, 3) at each waypoint: central differences inside a path."""
    N = len(position)
    t = np.zeros((N, 3))
    if N < 2:
        return t
    same_next = np.zeros(N, dtype=bool)
    same_next[:-1] = path[1:] == path[:-1]
    same_prev = np.zeros(N, dtype=bool)
    same_prev[1:] = path[1:] == path[:-1]
    nxt = np.where(same_next, np.roll(np.arange(N), -1), np.arange(N))
    prv = np.where(same_prev, np.roll(np.arange(N), 1), np.arange(N))
    t = position[nxt] - position[prv]
    n = np.linalg.norm(t, axis=1, keepdims=True)
    return t / np.where(n > tol.zero, n, 1.0)




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


REPEAT_DT_S = 1e-6  # time step given to a sample that repeats the previous pose


def moving_samples(q: np.ndarray) -> np.ndarray:
    """(M,) bool: False for samples whose joints equal the previous sample's (to 1e-6 rad)."""
    keep = np.ones(len(q), dtype=bool)
    if len(q) > 1:
        keep[1:] = np.abs(np.diff(q, axis=0)).max(axis=1) > tol.still
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


def insert_between(reach: Reach, samples: Samples, orient: Orientation, sub: Subdivision
                   ) -> tuple[Samples, Orientation]:
    """Samples and orientation with the samples of ``sub`` (``continuity.subdivide``)
    inserted, checked like the others (collisions, and alpha against their step's chord)."""
    if len(sub.step) == 0:
        return samples, orient
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
    return new_samples, new_orient


def with_moves(reach: Reach, samples: Samples, orient: Orientation, entry: SafeMove,
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
