"""Keep the nozzle on the path between trajectory samples: subdivide where the joints swing.

Why: the robot moves linearly in joint space between trajectory samples (the streamer
interpolates q at the servo rate). Far from singularities a 1 mm step moves every joint by a
fraction of a degree and the tip stays within microns of the straight step. Near the shoulder
singularity (the wrist centre close to the base axis: a nozzle tilted towards the robot) a
small change of tool pose turns the shoulder and wrist by tens of degrees, and so does a
repaired sample whose lean or spin differs from its neighbours'. Interpolated in joint space
such a step swings the tip off the path: 10-37 mm on the bundled socket and dome jobs, through
printed material, before this module existed.

How: for every step, the tip of the joint-space midpoint against the midpoint of the straight
step (``swing``). Steps beyond ``tol_mm`` get samples inserted at poses interpolated along the
step (tip on the straight step, tool rotation by spherical interpolation), solved by inverse
kinematics on the same branch and wrapped next to the step's first configuration, and are
split again until every piece is within the tolerance or ``max_depth`` halvings are spent.
The joints then turn as fast as the pose demands, and the time law (``timing.time_law``)
slows the motion to keep them within their limits. Inserted samples are checked like every
other (limits, singularity, clearance).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from scipy.spatial.transform import Rotation

from planner import kinematics as kin

SWING_TOL_MM = 0.05  # the tip may leave the straight step by this much between two samples
MAX_DEPTH = 8  # halvings of one step at most (256 pieces)


def swing(q: np.ndarray, tool_m: np.ndarray) -> np.ndarray:
    """(M - 1,) float64, mm: per step of configurations ``q`` (M, 6) rad, the distance of the
    tip at the joint-space midpoint from the midpoint of the straight step between the tips.
    ``tool_m``: (4, 4) tool transform in m."""
    if len(q) < 2:
        return np.zeros(0)
    tip = kin.fk(q, tool_m)[:, :3, 3]  # each configuration once: steps share their ends
    return _bow(tip[:-1], tip[1:], 0.5 * (q[:-1] + q[1:]), tool_m)


def pair_swing(q0: np.ndarray, q1: np.ndarray, tool_m: np.ndarray) -> np.ndarray:
    """(K,) float64, mm, ``swing`` of K separate steps q0 -> q1, both (K, 6) rad."""
    return _bow(kin.fk(q0, tool_m)[:, :3, 3], kin.fk(q1, tool_m)[:, :3, 3], 0.5 * (q0 + q1),
                tool_m)


def _bow(tip0: np.ndarray, tip1: np.ndarray, q_mid: np.ndarray, tool_m: np.ndarray
         ) -> np.ndarray:
    """(K,) mm, distance of the tip at ``q_mid`` from the midpoint of tips (K, 3) m."""
    mid = kin.fk(q_mid, tool_m)[:, :3, 3]
    out: np.ndarray = np.linalg.norm(mid - 0.5 * (tip0 + tip1), axis=1) * 1000.0
    return out


class Subdivision(NamedTuple):
    """Where steps were split.

    step: (S,) int64, index of the step (between samples step and step + 1) each new sample
        lies on; fraction: (S,) float64 in (0, 1), its position along the step; q: (S, 6)
        float64, rad, its configuration (points without an inverse kinematics solution are
        left out).
    worst_mm: float, largest swing left over the split steps (their pieces; 0 if none).
    """

    step: np.ndarray
    fraction: np.ndarray
    q: np.ndarray
    worst_mm: float


def subdivide(q: np.ndarray, solve: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray],
              tool_m: np.ndarray, tol_mm: float = SWING_TOL_MM,
              max_depth: int = MAX_DEPTH) -> Subdivision:
    """Samples to insert so that no step of ``q`` (M, 6) swings more than ``tol_mm``.

    Every step that swings is halved, and each half that still swings again, up to
    ``max_depth`` times; all pieces of one depth are solved at once.

    Args:
        q: (M, 6) float64, rad, the configurations along the path (continuous).
        solve: (tcp (S, 3) mm, R (S, 3, 3), q_ref (S, 6)) -> (S, 6) rad, inverse kinematics
            on the trajectory's branch wrapped next to ``q_ref`` (``reach.Reach.solve``).
        tool_m: (4, 4) tool transform in m.
    """
    def nothing(worst: float) -> Subdivision:
        return Subdivision(np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 6)), worst)

    bad = np.flatnonzero(swing(q, tool_m) > tol_mm)
    if bad.size == 0:
        return nothing(0.0)
    Ta = kin.fk(q[bad], tool_m)
    Tb = kin.fk(q[bad + 1], tool_m)
    tip_a, tip_b = Ta[:, :3, 3] * 1000.0, Tb[:, :3, 3] * 1000.0
    rot_a = Rotation.from_matrix(Ta[:, :3, :3])
    # the rotation from a to b as a vector: a fraction f of it is the spherical interpolation
    rel = (rot_a.inv() * Rotation.from_matrix(Tb[:, :3, :3])).as_rotvec()
    # pieces still to check: owner (which bad step), ends f0 < f1 and their configurations
    owner = np.arange(len(bad))
    f0, f1 = np.zeros(len(bad)), np.ones(len(bad))
    q0, q1 = q[bad], q[bad + 1]
    new_owner, new_f, new_q = [], [], []
    worst = 0.0
    for depth in range(max_depth + 1):
        off = pair_swing(q0, q1, tool_m)
        split = np.flatnonzero(off > tol_mm)
        if split.size == 0:
            break
        if depth == max_depth:
            worst = float(off.max())
            break
        o = owner[split]
        fm = 0.5 * (f0[split] + f1[split])
        R = (rot_a[o] * Rotation.from_rotvec(fm[:, None] * rel[o])).as_matrix()
        qm = solve(tip_a[o] + fm[:, None] * (tip_b[o] - tip_a[o]), R, q0[split])
        ok = ~np.isnan(qm).any(axis=1)
        if not ok.all():  # no solution inside the step there: the checks report it
            worst = max(worst, float(off[split[~ok]].max()))
        split, o, fm, qm = split[ok], o[ok], fm[ok], qm[ok]
        new_owner.append(o)
        new_f.append(fm)
        new_q.append(qm)
        owner = np.concatenate([o, o])
        f0, f1 = np.concatenate([f0[split], fm]), np.concatenate([fm, f1[split]])
        q0, q1 = np.concatenate([q0[split], qm]), np.concatenate([qm, q1[split]])
        if owner.size == 0:
            break
    if not new_owner:
        return nothing(worst)
    o_all = np.concatenate(new_owner)
    f_all = np.concatenate(new_f)
    order = np.lexsort((f_all, o_all))
    return Subdivision(bad[o_all[order]], f_all[order], np.concatenate(new_q)[order], worst)
