"""UR5e kinematics: vectorised forward kinematics, geometric Jacobian, closed-form IK.

Everything here works in metres and radians (design.md allows metres inside kinematics);
callers convert at one boundary (``planner.frames``). Arrays carry any leading batch shape
``...``: ``q`` is ``(..., 6)``, poses are ``(..., 4, 4)``.

The DH parameters are the official e-series numbers (standard DH, frame i after
Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)); ``rtb_robot`` builds the same arm as a
roboticstoolbox ``DHRobot`` for cross-checks.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from core.tolerance import tol

# UR5e e-series DH parameters, m and rad.
D = np.array([0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996])
A = np.array([0.0, -0.425, -0.3922, 0.0, 0.0, 0.0])
ALPHA = np.array([np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0])

# IK branch b = 4 * shoulder + 2 * wrist + elbow, each bit 0 -> "+" root, 1 -> "-" root.
BRANCHES = 8


def rtb_robot() -> Any:
    """The UR5e (e-series DH) as a roboticstoolbox ``DHRobot`` (imported lazily: slow)."""
    import roboticstoolbox as rtb

    links = [rtb.RevoluteDH(d=D[i], a=A[i], alpha=ALPHA[i]) for i in range(6)]
    return rtb.DHRobot(links, name="UR5e")


def dh_transform(theta: np.ndarray, i: int) -> np.ndarray:
    """Transform of DH link ``i`` for joint angles ``theta`` (...,) rad -> (..., 4, 4), m."""
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(ALPHA[i]), np.sin(ALPHA[i])
    T = np.zeros((*np.shape(theta), 4, 4))
    T[..., 0, 0] = ct
    T[..., 0, 1] = -st * ca
    T[..., 0, 2] = st * sa
    T[..., 0, 3] = A[i] * ct
    T[..., 1, 0] = st
    T[..., 1, 1] = ct * ca
    T[..., 1, 2] = -ct * sa
    T[..., 1, 3] = A[i] * st
    T[..., 2, 1] = sa
    T[..., 2, 2] = ca
    T[..., 2, 3] = D[i]
    T[..., 3, 3] = 1.0
    return T


def chain(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """DH frames and link-body frames in the base frame, by column updates (no 4x4 products).

    Returns:
        frames: (..., 7, 4, 4), m, DH frames 0..6 (0 = base, 6 = flange); joint i+1 rotates
            about the z axis of frame i.
        bodies: (..., 6, 4, 4), m, body i+1 = frame i rotated by q_{i+1} (link geometry is
            fixed in it).
    """
    q = np.asarray(q, dtype=float)
    batch = q.shape[:-1]
    x = np.broadcast_to(np.array([1.0, 0.0, 0.0]), (*batch, 3))
    y = np.broadcast_to(np.array([0.0, 1.0, 0.0]), (*batch, 3))
    z = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (*batch, 3))
    p = np.zeros((*batch, 3))
    # contiguous (..., 3, 4) blocks stacked once: strided writes into 4x4 arrays are slow
    frame_list = [np.stack([x, y, z, p], axis=-1)]
    body_list = []
    c, s = np.cos(q)[..., None], np.sin(q)[..., None]
    for i in range(6):  # six links
        xr = c[..., i, :] * x + s[..., i, :] * y
        yr = c[..., i, :] * y - s[..., i, :] * x
        body_list.append(np.stack([xr, yr, z, p], axis=-1))
        p = p + D[i] * z + A[i] * xr
        ca, sa = np.cos(ALPHA[i]), np.sin(ALPHA[i])
        x, y, z = xr, ca * yr + sa * z, ca * z - sa * yr
        frame_list.append(np.stack([x, y, z, p], axis=-1))
    return _homogeneous(np.stack(frame_list, axis=-3)), _homogeneous(np.stack(body_list, axis=-3))


def _homogeneous(top: np.ndarray) -> np.ndarray:
    """(..., 3, 4) -> (..., 4, 4) with the row [0, 0, 0, 1] appended."""
    bottom = np.zeros((*top.shape[:-2], 1, 4))
    bottom[..., 0, 3] = 1.0
    return np.concatenate([top, bottom], axis=-2)


def frames(q: np.ndarray) -> np.ndarray:
    """All DH frames 0..6 in the base frame: (..., 6) rad -> (..., 7, 4, 4), m.

    Frame 0 is the base, frame 6 the flange; joint i+1 rotates about the z axis of frame i.
    """
    return chain(q)[0]


def fk(q: np.ndarray, tool: np.ndarray | None = None, chunk: int = 16384) -> np.ndarray:
    """Flange pose (or tool pose if ``tool`` (4, 4) m is given): (..., 6) -> (..., 4, 4), m.

    Only the end frame is built, in cache-sized chunks (large temporaries cost more than the
    arithmetic here).
    """
    q = np.asarray(q, dtype=float)
    flat = q.reshape(-1, 6)
    out = np.empty((len(flat), 4, 4))
    for start in range(0, len(flat), chunk):
        out[start : start + chunk] = _end_frame(flat[start : start + chunk])
    T = out.reshape(*q.shape[:-1], 4, 4)
    return T if tool is None else T @ tool


def _end_frame(q: np.ndarray) -> np.ndarray:
    """Flange poses (n, 4, 4) of configurations (n, 6), by column updates."""
    n = len(q)
    x = np.zeros((n, 3))
    y = np.zeros((n, 3))
    z = np.zeros((n, 3))
    x[:, 0] = y[:, 1] = z[:, 2] = 1.0
    p = np.zeros((n, 3))
    c, s = np.cos(q)[:, :, None], np.sin(q)[:, :, None]
    for i in range(6):  # six links
        xr = c[:, i] * x + s[:, i] * y
        yr = c[:, i] * y - s[:, i] * x
        p = p + D[i] * z + A[i] * xr
        ca, sa = np.cos(ALPHA[i]), np.sin(ALPHA[i])
        x, y, z = xr, ca * yr + sa * z, ca * z - sa * yr
    return _homogeneous(np.stack([x, y, z, p], axis=-1))


def jacobian(q: np.ndarray, tool: np.ndarray | None = None) -> np.ndarray:
    """Geometric Jacobian in the base frame: (..., 6) -> (..., 6, 6).

    Rows 0-2 map joint rates (rad/s) to the linear velocity (m/s) of the flange origin (or of
    the tool point if ``tool`` (4, 4) m is given), rows 3-5 to the angular velocity (rad/s).
    """
    F = frames(q)
    end = F[..., 6, :, :] if tool is None else F[..., 6, :, :] @ tool
    z = F[..., :6, :3, 2]  # (..., 6, 3) joint axes
    o = F[..., :6, :3, 3]  # (..., 6, 3) joint origins
    lin = np.cross(z, end[..., None, :3, 3] - o)
    J = np.empty((*np.shape(q)[:-1], 6, 6))
    J[..., :3, :] = np.swapaxes(lin, -1, -2)
    J[..., 3:, :] = np.swapaxes(z, -1, -2)
    return J


def _inv(T: np.ndarray) -> np.ndarray:
    """Inverse of rigid transforms (..., 4, 4)."""
    out = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def ik(flange: np.ndarray, branches: tuple[int, ...] = tuple(range(BRANCHES))) -> tuple[
    np.ndarray, np.ndarray
]:
    """Closed-form inverse kinematics of the UR5e, vectorised over poses.

    Args:
        flange: (..., 4, 4) float64, m, flange poses in the base frame.
        branches: which of the 8 branches to solve (b = 4*shoulder + 2*wrist + elbow).

    Returns:
        q: (..., B, 6) float64, rad in (-pi, pi]; undefined (nan) where not valid.
        valid: (..., B) bool, the branch has a real solution (pose within reach).
    At a wrist singularity (sin q5 = 0) q6 is not determined; 0 is returned for it.
    """
    flange = np.asarray(flange, dtype=float)
    batch = flange.shape[:-2]
    R = flange[..., :3, :3]
    p = flange[..., :3, 3]
    b = np.asarray(branches)
    shoulder = np.where((b // 4) % 2 == 0, 1.0, -1.0)
    wrist = np.where((b // 2) % 2 == 0, 1.0, -1.0)
    elbow = np.where(b % 2 == 0, 1.0, -1.0)

    # q1 from the wrist centre (origin of frame 5) seen from above
    p05 = p - D[5] * R[..., :, 2]
    r = np.hypot(p05[..., 0], p05[..., 1])
    ratio = D[3] / np.maximum(r, tol.zero)
    ok = ratio <= 1.0
    phi = np.arccos(np.clip(ratio, -1.0, 1.0))
    q1 = (np.arctan2(p05[..., 1], p05[..., 0]))[..., None] + shoulder * phi[..., None] + np.pi / 2
    s1, c1 = np.sin(q1), np.cos(q1)

    # q5 from the flange position along the q1-normal
    c5 = (p[..., None, 0] * s1 - p[..., None, 1] * c1 - D[3]) / D[5]
    ok = ok[..., None] & (np.abs(c5) <= 1.0 + tol.slack)
    q5 = wrist * np.arccos(np.clip(c5, -1.0, 1.0))
    s5 = np.sin(q5)
    s5_safe = np.where(np.abs(s5) < tol.singular, 1.0, s5)
    y = (-R[..., None, 0, 1] * s1 + R[..., None, 1, 1] * c1) / s5_safe
    x = (R[..., None, 0, 0] * s1 - R[..., None, 1, 0] * c1) / s5_safe
    q6 = np.where(np.abs(s5) < tol.singular, 0.0, np.arctan2(y, x))

    # planar 3R problem for q2, q3, q4
    T14 = (
        _inv(dh_transform(q1, 0))
        @ flange[..., None, :, :]
        @ _inv(dh_transform(q5, 4) @ dh_transform(q6, 5))
    )
    # frame 4's origin lies in the x-y plane of frame 1 (joints 2-4 rotate about z1)
    px, py = T14[..., 0, 3], T14[..., 1, 3]
    c3 = (px**2 + py**2 - A[1] ** 2 - A[2] ** 2) / (2 * A[1] * A[2])
    ok = ok & (np.abs(c3) <= 1.0 + tol.slack)
    q3 = elbow * np.arccos(np.clip(c3, -1.0, 1.0))
    q2 = np.arctan2(py, px) - np.arctan2(A[2] * np.sin(q3), A[1] + A[2] * np.cos(q3))
    T34 = _inv(dh_transform(q2, 1) @ dh_transform(q3, 2)) @ T14
    q4 = np.arctan2(T34[..., 1, 0], T34[..., 0, 0])

    q = np.stack([q1, q2, q3, q4, q5, q6], axis=-1)
    q = (q + np.pi) % (2 * np.pi) - np.pi
    q = np.where(ok[..., None], q, np.nan)
    return q.reshape(*batch, len(b), 6), ok.reshape(*batch, len(b))


def branch_of(q: np.ndarray) -> np.ndarray:
    """The IK branch index (...,) int of configurations ``q`` (..., 6) rad."""
    q = np.asarray(q, dtype=float)
    T = fk(q)
    sol, ok = ik(T)
    d = np.abs(np.angle(np.exp(1j * (sol - q[..., None, :]))))
    d = np.where(ok[..., None], d, np.inf).max(axis=-1)
    return np.argmin(d, axis=-1)


def sigma_min(J: np.ndarray) -> np.ndarray:
    """Smallest singular value of Jacobians (..., 6, 6) -> (...,), with translation in m."""
    return np.linalg.svd(J, compute_uv=False)[..., -1]


def singularity_margin(q: np.ndarray) -> np.ndarray:
    """Distance (...,) from the three UR singularities, 0 at a singular pose, ~1 far away.

    det J = a2 a3 sin(q3) sin(q5) (a2 cos q2 + a3 cos(q2+q3) + d5 sin(q2+q3+q4)) factors into
    the elbow (q3 = 0), wrist (q5 = 0) and shoulder (wrist centre on the q1 axis) singularities;
    the margin is the smallest of |sin q3|, |sin q5| and the shoulder factor over |a2| + |a3|.
    Cheap and exact in where it vanishes, unlike an SVD per pose.
    """
    q = np.asarray(q, dtype=float)
    q2, q3, q4, q5 = q[..., 1], q[..., 2], q[..., 3], q[..., 4]
    shoulder = np.abs(A[1] * np.cos(q2) + A[2] * np.cos(q2 + q3) + D[4] * np.sin(q2 + q3 + q4))
    return np.minimum(
        np.minimum(np.abs(np.sin(q3)), np.abs(np.sin(q5))), shoulder / (abs(A[1]) + abs(A[2]))
    )
