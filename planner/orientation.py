"""Nozzle orientation per sample: axis along -normal, spin free, tilt and lean where needed.

The nozzle axis (tool z, out of the tip) is ``-normal`` at alpha = 90 deg; alpha is the angle
between the axis and the direction of motion. Rotation ``psi`` about the axis is the free
redundancy of the 6-axis arm. Two rotations move the axis off ``-normal`` where limits,
singularities or collisions demand it: a *tilt* in the plane of normal and motion (it changes
alpha, so it is bounded by [alpha_min, alpha_max]) and a *lean* about the direction of motion
(it keeps alpha, bounded by ``lean_max_deg``); on steep layer regions the lean swings the
holder and extruder body back over the part, out of the gel and away from the tank walls.
``planner.reach.Reach`` checks each pose (IK on the home branch, joint limits with margin,
singularity, clearance; the axis geometry is ``planner.nozzle_axis``); ``choose`` picks psi
by dynamic programming over a subsample (margins as cost, smooth spin), then, only where a
sample fails, the (tilt, lean) pair with the smallest deviation from ``-normal`` (a lean
before a tilt of the same size), ramping both in and out at 1 deg per sample.
Positions here are mm, angles rad.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from core.tolerance import tol
from planner.cell import CellConfig
from planner.nozzle_axis import alpha_of, alpha_within, nozzle_axis, tool_rotation
from planner.reach import ALPHA, COLLISION, JOINT_LIMIT, OK, Evaluation, Reach


@dataclass(frozen=True)
class Orientation:
    """The chosen orientation of every sample.

    Attributes:
        q: (M, 6) float64, rad, continuous along the job (nan where no IK solution at all).
        axis: (M, 3) float64, unit nozzle axis in the base frame.
        psi: (M,) float64, rad, spin about the axis (unwrapped).
        tilt: (M,) float64, rad, turn of the axis from -normal towards the motion
            (alpha = alpha0 - tilt, see ``nozzle_axis``).
        lean: (M,) float64, rad, turn of the axis about the motion direction (keeps alpha).
        status: (M,) int8, OK or the reason the sample is not reachable within limits.
        pair: (M,) int32, closest collision pair where clearance was computed, else -1.
        clearance: (M,) float64, mm, clearance where computed (every few samples and densely
            near the requirement), nan elsewhere.
    """

    q: np.ndarray
    axis: np.ndarray
    psi: np.ndarray
    tilt: np.ndarray
    lean: np.ndarray
    status: np.ndarray
    pair: np.ndarray
    clearance: np.ndarray


def tilt_levels(cell: CellConfig, alpha0: np.ndarray, step_deg: float = 5.0) -> np.ndarray:
    """Tilts (rad) to try, smallest first (0, +5, -5, +10, ... deg), covering every tilt that
    brings some sample's alpha = alpha0 - tilt into [alpha_min, alpha_max] (at most 45 deg)."""
    lo, hi = cell.planning.alpha_min_deg, cell.planning.alpha_max_deg
    a0 = np.degrees(alpha0) if len(alpha0) else np.array([90.0])
    t_min = max(float(a0.min()) - hi, -45.0)
    t_max = min(float(a0.max()) - lo, 45.0)
    k = np.arange(np.ceil(t_min / step_deg), np.floor(t_max / step_deg) + 1) * step_deg
    k = np.union1d(k, [0.0])
    order = np.lexsort((-k, np.abs(k)))  # by size, positive first
    return np.radians(k[order])


def orientation_levels(cell: CellConfig, alpha0: np.ndarray, tilt_step_deg: float = 5.0,
                       lean_step_deg: float = 5.0) -> np.ndarray:
    """(tilt, lean) pairs (L, 2) rad to try, by deviation from -normal, smallest first.

    Tilts as ``tilt_levels``; leans from -lean_max_deg to lean_max_deg. Among pairs of equal
    deviation a pure lean comes first (it keeps alpha at alpha0), then positive before negative.
    """
    tilts = np.degrees(tilt_levels(cell, alpha0, tilt_step_deg))
    lmax = cell.planning.lean_max_deg
    n = int(np.floor(lmax / lean_step_deg + tol.slack))
    leans = np.union1d(np.arange(-n, n + 1) * lean_step_deg, [0.0])
    T, L = np.meshgrid(tilts, leans, indexing="ij")
    T, L = T.ravel(), L.ravel()
    dev = np.degrees(np.arccos(np.cos(np.radians(T)) * np.cos(np.radians(L))))
    order = np.lexsort((-L, -T, np.abs(T), np.round(dev, 6)))
    return np.radians(np.stack([T[order], L[order]], axis=1))


def _viterbi(cost: np.ndarray, grid: np.ndarray, weight: float) -> np.ndarray:
    """Cheapest state sequence: node cost (S, K) plus weight * (wrapped spin change)^2."""
    S, K = cost.shape
    d = np.angle(np.exp(1j * (grid[:, None] - grid[None, :])))
    trans = weight * d**2
    finite = np.where(np.isfinite(cost), cost, 1e6)
    acc = finite[0].copy()
    back = np.zeros((S, K), dtype=np.int64)
    for s in range(1, S):  # a loop over coarse samples (<= a few thousand), not elements
        tot = acc[None, :] + trans
        back[s] = np.argmin(tot, axis=1)
        acc = tot[np.arange(K), back[s]] + finite[s]
    path = np.empty(S, dtype=np.int64)
    path[-1] = int(np.argmin(acc))
    for s in range(S - 1, 0, -1):
        path[s - 1] = back[s, path[s]]
    return path


AXIS_CHECK_DEG = 2.0  # a sample whose axis is this far from its strided sample's is checked too
REPAIR_ROUNDS = 4  # repair, ramp, re-check: a ramp may break a neighbour, so repeat
REPAIR_BATCH = 2048  # poses per check while repairing (failing samples x candidates)


def ramp(dev: np.ndarray, per_sample: float) -> np.ndarray:
    """Spread deviations so they ramp in and out at ``per_sample`` rad per sample."""
    width = int(min(np.ceil(np.abs(dev).max() / per_sample), 2000)) if dev.size else 0
    if width == 0:
        return dev
    k = np.arange(-width, width + 1)
    structure = -per_sample * np.abs(k)
    pos = ndimage.grey_dilation(np.maximum(dev, 0.0), structure=structure, mode="nearest")
    neg = ndimage.grey_dilation(np.maximum(-dev, 0.0), structure=structure, mode="nearest")
    return np.maximum(pos, 0.0) - np.maximum(neg, 0.0)


def choose(
    reach: Reach,
    tcp: np.ndarray,
    normal: np.ndarray,
    tangent: np.ndarray,
    extrude: np.ndarray,
    coarse: int = 600,
    clearance_stride: int = 4,
    arrive: np.ndarray | None = None,
) -> Orientation:
    """Pick spin, tilt and lean for every sample (see module docstring).

    Args:
        tcp: (M, 3) float64, mm, nozzle tip targets in the base frame.
        normal: (M, 3) float64, unit printing directions in the base frame.
        tangent: (M, 3) float64, unit motion directions in the base frame.
        extrude: (M,) bool; alpha limits apply to extruding samples only.
        coarse: size of the subsample for the spin search.
        clearance_stride: full-resolution clearance every this many samples (plus every
            sample near the required clearance).
        arrive: (M, 3) float64, unit direction of the depositing step arriving at each sample
            (zero rows where the arriving step does not deposit); alpha must hold against it
            too. None: only ``tangent`` is checked.
    """
    cell = reach.cell
    M = len(tcp)

    def allowed(ax: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """(len(rows),) bool: alpha within range against the leaving and arriving steps."""
        return alpha_within(cell, ax, tangent[rows], extrude[rows],
                            None if arrive is None else arrive[rows])

    K = cell.planning.spin_steps
    grid = np.linspace(-np.pi, np.pi, K, endpoint=False)
    alpha0 = alpha_of(-normal, tangent)
    levels = orientation_levels(cell, alpha0)
    w_tilt, w_lean = np.radians(20.0), np.radians(28.0)  # a lean costs less than a tilt

    # 1. coarse spin search on a subsample, the axis moved off -normal only where needed
    sub = np.unique(np.append(np.linspace(0, M - 1, min(M, coarse)).round().astype(int), M - 1))
    S = len(sub)
    cost = np.full((S, K), np.inf)
    dev = np.zeros((S, K, 2))
    for tilt_l, lean_l in levels:
        todo = np.flatnonzero(~np.isfinite(cost).any(axis=1))
        if not len(todo):
            break
        idx = sub[todo]
        ax = nozzle_axis(normal[idx], tangent[idx], np.full(len(idx), tilt_l),
                         np.full(len(idx), lean_l))
        ax_r = np.repeat(ax, K, axis=0)
        psi = np.tile(grid, len(idx))
        R = tool_rotation(ax_r, psi)
        q = reach.solve(np.repeat(tcp[idx], K, axis=0), R, reach.home)
        ev = reach.check(q, iters=8)
        c = reach.cost(ev).reshape(len(idx), K) + (tilt_l / w_tilt) ** 2 + (lean_l / w_lean) ** 2
        c[~allowed(ax, idx)] = np.inf
        cost[todo] = c
        dev[todo] = (tilt_l, lean_l)
    path = _viterbi(cost, grid, weight=10.0)
    psi_sub = np.unwrap(grid[path])
    dev_sub = dev[np.arange(S), path]
    psi = np.interp(np.arange(M), sub, psi_sub)
    # ramp tilts and leans in and out (1 deg per sample) instead of stepping between levels
    per_sample = np.radians(1.0)
    tilt = ramp(np.interp(np.arange(M), sub, dev_sub[:, 0]), per_sample)
    lean = ramp(np.interp(np.arange(M), sub, dev_sub[:, 1]), per_sample)
    lo_a, hi_a = np.radians([cell.planning.alpha_min_deg, cell.planning.alpha_max_deg])
    tilt = np.where(extrude, np.clip(tilt, alpha0 - hi_a, alpha0 - lo_a), tilt)

    # 2. full resolution, then repair failing samples with the smallest change
    def evaluate(rows: np.ndarray, psi_r: np.ndarray, tilt_r: np.ndarray, lean_r: np.ndarray,
                 q_ref: np.ndarray, stride: int) -> tuple[np.ndarray, Evaluation, np.ndarray]:
        ax = nozzle_axis(normal[rows], tangent[rows], tilt_r, lean_r)
        q = reach.solve(tcp[rows], tool_rotation(ax, psi_r), q_ref)
        ev = reach.check(q, clearance=False)
        clear = np.full(len(rows), np.nan)
        pair = np.full(len(rows), -1, dtype=np.int32)
        has = ~np.isnan(q).any(axis=1)
        pick = np.zeros(len(rows), dtype=bool)
        pick[::stride] = True
        pick &= has
        if pick.any():
            c = reach.collision.clearance(q[pick])
            clear[pick], pair[pick] = c.distance, c.pair
            # densify where the strided clearance is close to the requirement
            near = np.flatnonzero(pick)[c.distance < cell.planning.clearance_mm + 5.0]
            if len(near) and stride > 1:
                extra = np.unique(np.clip(near[:, None] + np.arange(-stride, stride + 1), 0,
                                          len(rows) - 1))
            else:
                extra = np.zeros(0, dtype=np.int64)
            if stride > 1:
                # and where the nozzle turns away from the strided samples' axes: a sample
                # whose axis spikes (a layer curling at its edge) can reach the wall while
                # the samples on either side clear it by centimetres
                base = (np.arange(len(rows)) // stride) * stride
                turned = np.einsum("ij,ij->i", ax, ax[base]) < np.cos(np.radians(AXIS_CHECK_DEG))
                extra = np.union1d(extra, np.flatnonzero(turned))
            if len(extra):
                extra = extra[has[extra] & ~pick[extra]]
                if len(extra):
                    c2 = reach.collision.clearance(q[extra])
                    clear[extra], pair[extra] = c2.distance, c2.pair
        status = ev.status.copy()
        hit = has & (np.nan_to_num(clear, nan=np.inf) < cell.planning.clearance_mm)
        status[hit & (status == OK)] = COLLISION
        off = ~allowed(ax, rows)
        status[off & (status == OK)] = ALPHA
        ev = Evaluation(q, status, ev.singular, clear, ev.margin, pair)
        return q, ev, ax

    q_ref = _continuous_reference(reach, M)
    q, ev, axis = evaluate(np.arange(M), psi, tilt, lean, q_ref, clearance_stride)
    status = ev.status.copy()
    pair = ev.pair.copy()
    clearance = ev.clearance.copy()
    spins = np.radians([0.0, 15.0, -15.0, 30.0, -30.0, 60.0, -60.0, 90.0, -90.0])
    # (C, 3) repair candidates (tilt, lean, spin change), levels first, then spins
    cand = np.column_stack([np.repeat(levels, len(spins), axis=0),
                            np.tile(spins, len(levels))])
    # a repair ramps into its neighbours, which may fail in turn: repeat a few rounds
    for round_ in range(REPAIR_ROUNDS):
        bad = np.flatnonzero(status != OK)
        if not len(bad):
            break
        new_psi, new_tilt, new_lean = psi.copy(), tilt.copy(), lean.copy()
        fixed = np.zeros(M, dtype=bool)
        c0, grow = 0, 1
        # candidates in order (levels, then spins within a level): each failing sample takes
        # the first that is OK. They are checked in blocks of candidates x failing samples
        # that double in size: few samples usually fail, and one call per candidate would
        # cost mostly overhead, one big block much work on samples an early candidate fixes
        while c0 < len(cand):  # a loop over blocks of candidates
            rows = bad[~fixed[bad]]
            if not len(rows):
                break
            b = int(min(grow, max(REPAIR_BATCH // len(rows), 1), len(cand) - c0))
            grow = 2 * b
            block = cand[c0:c0 + b]  # (b, 3): tilt, lean, spin
            c0 += b
            rr = np.repeat(rows, b)
            cb = np.tile(block, (len(rows), 1))
            _, e2, _ = evaluate(rr, psi[rr] + cb[:, 2], cb[:, 0], cb[:, 1], reach.home, 1)
            good = (e2.status == OK).reshape(len(rows), b)
            hit = good.any(axis=1)
            first = block[np.argmax(good, axis=1)[hit]]
            rows_ok = rows[hit]
            new_psi[rows_ok] = psi[rows_ok] + first[:, 2]
            new_tilt[rows_ok] = first[:, 0]
            new_lean[rows_ok] = first[:, 1]
            fixed[rows_ok] = True
        if not fixed.any():
            break
        # ramp the changes in and out so the wrist does not jump, then re-check what changed;
        # the last round sets the repairs without a ramp (where the motion direction turns
        # sharply, a ramp in tilt and lean can break the neighbours again and again)
        old_psi, old_tilt, old_lean = psi, tilt, lean
        if round_ == REPAIR_ROUNDS - 1:
            psi, tilt, lean = new_psi, new_tilt, new_lean
        else:
            psi = psi + ramp(new_psi - psi, per_sample)
            tilt = tilt + ramp(new_tilt - tilt, per_sample)
            lean = lean + ramp(new_lean - lean, per_sample)
        # keep extruding samples' alpha in range: alpha = alpha0 - tilt
        tilt = np.where(extrude, np.clip(tilt, alpha0 - hi_a, alpha0 - lo_a), tilt)
        changed = np.flatnonzero((np.abs(psi - old_psi) > tol.zero)
                                 | (np.abs(tilt - old_tilt) > tol.zero)
                                 | (np.abs(lean - old_lean) > tol.zero))
        if len(changed):
            q_c, ev_c, ax_c = evaluate(changed, psi[changed], tilt[changed], lean[changed],
                                       q_ref[changed], 1)
            q[changed], axis[changed] = q_c, ax_c
            status[changed], pair[changed] = ev_c.status, ev_c.pair
            clearance[changed] = ev_c.clearance
        # samples still failing take the candidate found for them, if any
        still = np.flatnonzero((status != OK) & fixed)
        if len(still):
            q2, e3, ax3 = evaluate(still, new_psi[still], new_tilt[still], new_lean[still],
                                   reach.home, 1)
            good = e3.status == OK
            rows = still[good]
            q[rows], axis[rows] = q2[good], ax3[good]
            psi[rows], tilt[rows], lean[rows] = new_psi[rows], new_tilt[rows], new_lean[rows]
            status[rows] = OK
            pair[rows], clearance[rows] = e3.pair[good], e3.clearance[good]
    q = _make_continuous(q, reach.home, reach.lo, reach.hi)
    lim_bad = np.any((q < reach.lo_safe) | (q > reach.hi_safe), axis=1) & (status == OK)
    status[lim_bad] = JOINT_LIMIT
    off = ~allowed(axis, np.arange(M)) & (status == OK)
    status[off] = ALPHA
    return Orientation(q, axis, psi, tilt, lean, status, pair, clearance)


def _continuous_reference(reach: Reach, M: int) -> np.ndarray:
    """Wrap reference for the first IK pass: home (continuity is restored afterwards)."""
    return np.broadcast_to(reach.home, (M, 6))


def _make_continuous(q: np.ndarray, home: np.ndarray, lo: np.ndarray,
                     hi: np.ndarray) -> np.ndarray:
    """Unwrap joint angles along the job (nan rows filled by interpolation), then shift each
    joint by the whole turns that keep most samples within its limits, nearest home."""
    q = q.copy()
    has = ~np.isnan(q).any(axis=1)
    if not has.any():
        return q
    idx = np.arange(len(q))
    # unwrap the solved rows first, then fill the gaps: interpolating wrapped angles across
    # a gap would sweep a joint through a whole turn
    q_has = np.unwrap(q[has], axis=0)
    for j in range(6):  # six joints
        q[:, j] = np.interp(idx, idx[has], q_has[:, j])
    q -= 2 * np.pi * np.round((q[0] - home) / (2 * np.pi))
    shifts = 2 * np.pi * np.array([0.0, -1.0, 1.0])
    for j in range(6):  # six joints, three candidate turns each
        outside = [np.sum((q[:, j] + d < lo[j]) | (q[:, j] + d > hi[j])) for d in shifts]
        q[:, j] += shifts[int(np.argmin(outside))]
    return q
