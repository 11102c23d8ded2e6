"""Jacobian-based joint velocities and time parameterisation within joint limits.

Joint rates per unit path parameter come from damped-least-squares differential kinematics
on the 5-D task (TCP position and nozzle axis direction):
``q' = J5^+ t5 + N5 z``, where ``N5`` projects on the one-dimensional null space (the spin
about the nozzle axis) and ``z`` moves along it at the spin rate the orientation search chose
from joint-limit, singularity and clearance margins. The path parameter s is a generalised
arc length (mm of TCP travel, or 50 mm per rad of tool rotation on steps where the TCP does
not move, so pure reorientations still advance s). The time law s(t) is the fastest that
keeps the TCP at the toolpath speed and every joint within its velocity and acceleration
limits (forward/backward passes on sdot^2, done as vectorised min-scans). Where a limit
forces the TCP slower than the toolpath speed, the extruder (running at the constant rate
C) over-deposits; ``Timing`` reports where.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.tolerance import tol
from planner import kinematics as kin
from planner.path_derivatives import neighbours, window_derivative
from planner.status import TimingStatus


@dataclass(frozen=True)
class Timing:
    """The time law of a sampled path.

    Attributes:
        t: (M,) float64, s, sample times from 0.
        qd: (M, 6) float64, rad/s, joint velocities.
        speed: (M,) float64, mm/s, TCP speed at each sample.
        target: (M,) float64, mm/s, toolpath speed asked for at each sample.
        limited: (M,) bool, a joint limit made the TCP slower than 99 % of the target.
        iterations: int, passes of the discrete acceleration check.
        status: "ok" or "acceleration limit not met after N passes".
    """

    t: np.ndarray
    qd: np.ndarray
    speed: np.ndarray
    target: np.ndarray
    limited: np.ndarray
    iterations: int
    status: str


def task_rates(
    q: np.ndarray, tcp_mm: np.ndarray, axis: np.ndarray, omega: np.ndarray, s: np.ndarray,
    tool_m: np.ndarray, damping: float, chunk: int = 8192, side: np.ndarray | None = None,
) -> np.ndarray:
    """Joint rates along the path, dq/ds (M, 6) rad/mm, by DLS with a null-space spin term.

    Args:
        q: (M, 6) float64, rad, configurations at the samples.
        tcp_mm: (M, 3) float64, mm, TCP positions (base frame).
        axis: (M, 3) float64, unit nozzle axes.
        omega: (M, 3) float64, rad/mm, tool angular velocity along the path (base frame);
            its part about the axis is the spin the null-space term realises.
        s: (M,) float64, mm, path parameter at the samples (strictly increasing).
        tool_m: (4, 4) float64, m, tool transform (flange -> tip).
        damping: float, largest DLS damping (m-scaled), applied as the manipulator nears a
            singularity.
        side: (M,) int8 or None, ``path_derivatives.junctions``: -1 / +1 where the TCP
            velocity is taken from the arriving / leaving step alone (``omega`` must be taken
            the same way).
    """
    M = len(q)
    out = np.empty((M, 6))
    # path derivatives by central differences over the sample index (one-sided at the ends
    # and at junctions)
    dp = np.gradient(tcp_mm / 1000.0, s, axis=0) if M > 1 else np.zeros((M, 3))  # m/mm
    if side is not None and M > 1:
        nxt, prv = neighbours(M, side)
        one = np.flatnonzero(side != 0)
        dp[one] = (tcp_mm[nxt[one]] - tcp_mm[prv[one]]) / 1000.0 \
            / (s[nxt[one]] - s[prv[one]])[:, None]
    for start in range(0, M, chunk):
        sl = slice(start, start + chunk)
        J = kin.jacobian(q[sl], tool_m)  # (m, 6, 6)
        a = axis[sl]
        w = omega[sl]
        # 5-D task: linear velocity (3) and the angular velocity in two directions normal to a
        e1 = _perp(a)
        e2 = np.cross(a, e1)
        J5 = np.concatenate(
            [
                J[:, :3, :],
                np.einsum("mi,mij->mj", e1, J[:, 3:, :])[:, None, :],
                np.einsum("mi,mij->mj", e2, J[:, 3:, :])[:, None, :],
            ],
            axis=1,
        )
        t5 = np.concatenate(
            [
                dp[sl],
                np.einsum("mi,mi->m", e1, w)[:, None],
                np.einsum("mi,mi->m", e2, w)[:, None],
            ],
            axis=1,
        )
        # damping grows as the pose nears a singularity (analytic margin, no SVD per pose)
        sv = kin.singularity_margin(q[sl])
        threshold = 0.1
        lam2 = np.where(sv < threshold, damping**2 * (1.0 - (sv / threshold) ** 2), 0.0)
        A5 = J5 @ np.swapaxes(J5, 1, 2) + lam2[:, None, None] * np.eye(5)
        x = np.linalg.solve(A5, t5[..., None])[..., 0]
        qd_task = np.einsum("mji,mj->mi", J5, x)
        # null space of J5: the joint motion that only spins the tool about its axis
        n = _null_vector(J, a, lam2)
        spin_per_n = np.einsum("mi,mij,mj->m", a, J[:, 3:, :], n)
        spin_task = np.einsum("mi,mij,mj->m", a, J[:, 3:, :], qd_task)
        usable = np.abs(spin_per_n) > tol.floor
        spin_err = np.einsum("mi,mi->m", a, w) - spin_task
        z = np.where(usable, spin_err / np.where(usable, spin_per_n, 1.0), 0.0)
        out[sl] = qd_task + z[:, None] * n
    return out


def angular_rates(R: np.ndarray, s: np.ndarray | None = None,
                  side: np.ndarray | None = None) -> np.ndarray:
    """Angular velocity along the path (M, 3), base frame, of orientations R (M, 3, 3).

    Central differences of the rotation: omega_k = log(R_{k+1} R_{k-1}^T) / (s_{k+1} - s_{k-1})
    (one-sided at the ends and where ``side`` (M,) int8 says: ``junctions``); rad per unit of
    ``s`` (M,), or per sample if ``s`` is None.
    """
    M = len(R)
    if M < 2:
        return np.zeros((M, 3))
    nxt, prv = neighbours(M, side)
    W = R[nxt] @ np.swapaxes(R[prv], 1, 2)
    steps = (nxt - prv).astype(float) if s is None else s[nxt] - s[prv]
    cos = np.clip((np.trace(W, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cos)
    v = np.stack([W[:, 2, 1] - W[:, 1, 2], W[:, 0, 2] - W[:, 2, 0], W[:, 1, 0] - W[:, 0, 1]], 1)
    s = np.sin(angle)
    scale = np.where(s > tol.floor, angle / (2 * np.where(s > tol.floor, s, 1.0)), 0.5)
    return v * scale[:, None] / steps[:, None]


def _perp(a: np.ndarray) -> np.ndarray:
    ref = np.where(np.abs(a[:, :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    v = np.cross(a, ref)
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _null_vector(J: np.ndarray, a: np.ndarray, lam2: np.ndarray) -> np.ndarray:
    """Unit joint motion (m, 6) that spins the tool about ``a`` and moves nothing else.

    It spans the null space of the 5-D task Jacobian: J6 n = [0, 0, 0, a] (damped like the
    task solution near singularities).
    """
    rhs = np.concatenate([np.zeros_like(a), a], axis=1)
    A6 = J @ np.swapaxes(J, 1, 2) + lam2[:, None, None] * np.eye(6)
    n = np.einsum("mji,mj->mi", J, np.linalg.solve(A6, rhs[..., None])[..., 0])
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(norm > tol.direction, norm, 1.0)


MIN_DT = 1e-6  # s, shortest step of the time law
MIN_ACC = 1e-6  # rad/s^2, the acceleration a step between two rests is given at least


# The joint path's curvature q'' is taken over +-this arc length, not between neighbouring
# samples: their spacing (0.02-2 mm, with the continuity stage's inserts) turns a small kink
# of q' into a large second difference, and the curvature cap then slows the nozzle at that
# one sample (a speed profile jumping 4 -> 1.3 -> 2.5 -> 1.2 mm/s on a torus). The discrete
# acceleration check of ``time_law`` still holds every step to the limit.
CURVATURE_WINDOW_MM = 0.5


def _scan_limit(cap: np.ndarray, inc: np.ndarray) -> np.ndarray:
    """x_k = min(cap_k, x_{k-1} + inc_{k-1}) for all k at once (x_0 = cap_0)."""
    S = np.concatenate([[0.0], np.cumsum(inc)])
    return np.minimum.accumulate(cap - S) + S


def time_law(
    q: np.ndarray, dq: np.ndarray, tcp_mm: np.ndarray, s: np.ndarray, target: np.ndarray,
    vmax: np.ndarray, amax: np.ndarray, max_iter: int = 30, stop: np.ndarray | None = None,
    side: np.ndarray | None = None,
) -> Timing:
    """Fastest time law within limits and the toolpath speed (see module docstring).

    Args:
        q: (M, 6) float64, rad. dq: (M, 6) float64, rad/mm, dq/ds (from ``task_rates``).
        tcp_mm: (M, 3) float64, mm. s: (M,) float64, mm, path parameter (increasing).
        target: (M,) float64, mm/s, toolpath speed per sample.
        vmax, amax: (6,) float64, rad/s and rad/s^2 joint limits.
        stop: (M,) bool or None, samples where the motion comes to rest (besides the first
            and the last): the corners between a joint-space move, a plunge along the nozzle
            axis and the toolpath, where the joint velocity direction jumps.
        side: (M,) int8 or None, ``junctions`` (where deposition stops and starts): ``dq``
            there is one-sided, and the curvature window does not reach across them.
    """
    M = len(q)
    if M < 2:
        z = np.zeros(M)
        return Timing(z, np.zeros((M, 6)), z, target, np.zeros(M, bool), 0, "ok")
    # TCP speed on a step is |dp|/ds times the mean sdot of its ends, so the speed cap at a
    # sample uses the larger |dp|/ds of its two steps (1 where the TCP travels)
    ratio = np.linalg.norm(np.diff(tcp_mm, axis=0), axis=1) / np.diff(s)
    dp = np.maximum(np.r_[ratio[:1], ratio], np.r_[ratio, ratio[-1:]])
    if M == 2:
        # one step from rest to rest: the slowest of speed, velocity and bang-bang bounds
        step = np.abs(q[1] - q[0])
        length = float(np.linalg.norm(tcp_mm[1] - tcp_mm[0]))
        dt1 = max(length / max(float(target[0]), tol.floor), float(np.max(step / vmax)),
                  float(np.max(2.0 * np.sqrt(step / amax))), MIN_DT)
        z = np.zeros((2, 6))
        return Timing(np.array([0.0, dt1]), z, np.zeros(2), target, np.zeros(2, bool), 0, "ok")
    ddq = window_derivative(dq, s, CURVATURE_WINDOW_MM, side)  # rad/mm^2, the constant
    ds = np.diff(s)
    safety = 0.98
    # velocity caps on x = sdot^2 (mm/s)^2: TCP speed and joint speed
    x_speed = np.where(dp > tol.floor, (target / np.maximum(dp, tol.floor)) ** 2, np.inf)
    x_joint = np.min((safety * vmax / np.maximum(np.abs(dq), tol.zero)) ** 2, axis=1)
    # the curvature term q'' sdot^2 may use at most half the acceleration budget
    x_curv = np.min(0.5 * safety * amax / np.maximum(np.abs(ddq), tol.zero), axis=1)
    cap = np.minimum(np.minimum(x_speed, x_joint), x_curv)
    # The robot moves linearly in joint space between samples, so each step must keep
    # |dq| / dt within the limits whatever the rates above say (a spin or lean changed at
    # one place, a pose next to a singularity): with both ends of a step below this cap,
    # dt = 2 ds / (sdot_k + sdot_k+1) >= |dq| / (safety vmax).
    x_step = np.min((safety * vmax * np.diff(s)[:, None]
                     / np.maximum(np.abs(np.diff(q, axis=0)), tol.zero)) ** 2, axis=1)
    cap[:-1] = np.minimum(cap[:-1], x_step)
    cap[1:] = np.minimum(cap[1:], x_step)
    cap = np.minimum(cap, 1e12)
    cap[0] = cap[-1] = 0.0
    if stop is not None:
        cap[np.asarray(stop, dtype=bool)] = 0.0
    status: str = TimingStatus.OK
    it = 0
    while True:  # a few passes, each fully vectorised
        it += 1
        # acceleration left for sddot: (amax - |q''| x) / |q'|, mm/s^2
        budget = np.min(
            (safety * amax - np.abs(ddq) * cap[:, None]) / np.maximum(np.abs(dq), tol.zero), axis=1
        )
        budget = np.maximum(budget, 0.0)
        inc = 2.0 * budget[:-1] * ds  # x_{k+1} - x_k <= 2 sddot ds
        x = _scan_limit(cap, inc)
        x = _scan_limit(x[::-1], (2.0 * budget[1:] * ds)[::-1])[::-1]  # decelerations
        x = np.maximum(x, 0.0)
        sd = np.sqrt(x)
        # at least MIN_DT per step: t (up to ~1e5 s on a long job) must visibly increase
        dt = np.maximum(2.0 * ds / np.maximum(sd[:-1] + sd[1:], tol.zero), MIN_DT)
        # a step between two rests: from rest to rest with the acceleration budget
        both = (sd[:-1] + sd[1:]) < tol.floor
        if both.any():
            acc_s = np.maximum(np.minimum(budget[:-1], budget[1:])[both], MIN_ACC)
            dt[both] = np.maximum(2.0 * np.sqrt(ds[both] / acc_s), MIN_DT)
        qd = dq * sd[:, None]
        acc = np.abs(np.diff(qd, axis=0)) / dt[:, None]
        ratio = np.max(acc / amax, axis=1)
        over = ratio > 1.0
        if not over.any():
            break
        if it >= max_iter:
            status = f"{TimingStatus.ACCELERATION} after {max_iter} passes"
            break
        # shrink the caps at both ends of each offending step and try again
        shrink = np.ones(M)
        f = (0.97 / ratio[over]) ** 2
        shrink[:-1][over] = np.minimum(shrink[:-1][over], f)
        shrink[1:][over] = np.minimum(shrink[1:][over], f)
        cap = np.minimum(cap, x * shrink)
    t = np.concatenate([[0.0], np.cumsum(dt)])
    speed = dp * sd  # mm/s
    limited = speed < 0.99 * target
    limited[0] = limited[-1] = False
    if stop is not None:
        limited[np.asarray(stop, dtype=bool)] = False
    return Timing(t, qd, speed, target, limited, it, status)


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
    ds = np.where(step > 1e-3, step, np.maximum(ROTATION_MM_PER_RAD * np.arccos(cos), tol.still))
    return np.concatenate([[0.0], np.cumsum(ds)])
