"""Width-driven deformation of a layer (paper section 4.3, eqs. 13 and 14).

Each face f is asked to become a rotated copy of itself scaled by s_f = 3 W_mean / sum W(x_i)
(eq. 14): where the target toolpath width W is large the surface shrinks, so a pattern of
constant spacing W_mean on the deformed layer maps back to spacing ~ W on the original.
Eq. 13 is solved by local-global iterations (ARAP style, [47]): the local step is the best
rotation per face (Kabsch; for planar triangles the 2x2 SVD has a closed form, vectorised),
the global step a sparse least-squares solve whose matrix depends only on connectivity and
the face areas and is factored once (sparse Cholesky). One vertex per component is pinned.

How many iterations: the solve stops once the achieved scale is within ``scale_tol`` of the
target on 90 % of the area (what the toolpath's width error sees), or when the energy stops
falling. A fixed handful is not enough where W varies a lot: on the membrane's dome layers
(sliced at 0.70 mm: W 1.0-6.9 mm within one layer) 6 iterations left the achieved scale
25-200 % off the target on a quarter of the faces and the stripe width error p50 at 33 %;
iterating to convergence (130-170 iterations, 2-3 s per layer) brings it to 14 %. Where W is
nearly constant (the socket: 1.4 % off before any iteration) one or two iterations reach the
tolerance.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from core.errors import InputError
from core.tolerance import tol
from slicer.status import DeformStatus
from slicer.toolpath.surface import check_mesh, components, face_normals, spd_solver


class DeformResult(NamedTuple):
    """Result of ``deform_to_constant_width``.

    vertices: (n, 3) float64 mm, deformed layer (same connectivity as the input).
    scale:    (m,) float64, target per-face scale s_f (eq. 14).
    achieved: (m,) float64, achieved per-face scale sqrt(area_deformed / area).
    status:   ``DeformStatus``: WITHIN_TOLERANCE (achieved scale within ``scale_tol`` of the
              target on 90 % of the area), CONVERGED (relative energy change below ``rtol``)
              or MAX_ITERATIONS.
    trace:    (k,) float64 mm^2, energy of eq. 13 after each iteration.
    deviation: float, area-weighted p90 of |achieved / scale - 1| at the result.
    """

    vertices: NDArray[np.float64]
    scale: NDArray[np.float64]
    achieved: NDArray[np.float64]
    status: DeformStatus
    trace: NDArray[np.float64]
    deviation: float


def scale_deviation(vertices: NDArray[np.float64], faces: NDArray[np.int64],
                    area: NDArray[np.float64], scale: NDArray[np.float64]
                    ) -> tuple[float, NDArray[np.float64]]:
    """Area-weighted p90 of |achieved / target - 1| and the achieved per-face scale (m,).

    vertices: (n, 3) float64 mm, the deformed layer; area: (m,) float64 mm^2, the faces'
    areas before deformation; scale: (m,) target per-face scale s_f.
    """
    _, area_d = face_normals(vertices, faces)
    achieved = np.sqrt(area_d / np.maximum(area, tol.tiny))
    dev = np.abs(achieved / scale - 1.0)
    order = np.argsort(dev)
    cum = np.cumsum(area[order])
    at = min(int(np.searchsorted(cum, 0.9 * cum[-1])), len(order) - 1)
    return float(dev[order[at]]), achieved


def face_scale(vertices: NDArray[np.float64], faces: NDArray[np.integer],
               width: NDArray[np.float64]) -> NDArray[np.float64]:
    """(m,) s_f = 3 W_mean / sum_i W(x_i) (eq. 14); W_mean is the area-weighted mean width."""
    _, area = face_normals(vertices, faces)
    w_face = width[faces].mean(axis=1)
    w_mean = float((w_face * area).sum() / max(area.sum(), tol.tiny))
    return w_mean / w_face


def _rotations(src: NDArray[np.float64], dst: NDArray[np.float64]) -> NDArray[np.float64]:
    """(m, 3, 3) best rotations R_f with R_f src_k ~ dst_k for centred corner stacks (m, 3, 3).

    Kabsch on a stack: SVD of the cross-covariance sum_k p_k q_k^T, reflections fixed by
    flipping the singular vector of the smallest singular value. (The solver uses the faster
    in-plane form ``_planar_targets``; this is its reference, used by the tests.)
    """
    h = np.einsum("fki,fkj->fij", src, dst)  # sum_k p_k q_k^T
    u, _, vt = np.linalg.svd(h)
    r = np.einsum("fji,fkj->fik", vt, u)  # V U^T
    bad = np.linalg.det(r) < 0
    if bad.any():
        vt_fix = vt[bad].copy()
        vt_fix[:, 2, :] *= -1.0
        r[bad] = np.einsum("fji,fkj->fik", vt_fix, u[bad])
    return r


def _frames(centred: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Orthonormal in-plane frames (e1, e2), each (m, 3), of centred triangles (m, 3, 3)."""
    e1 = centred[:, 1] - centred[:, 0]
    e1 /= np.maximum(np.linalg.norm(e1, axis=1), tol.tiny)[:, None]
    n = np.cross(centred[:, 1] - centred[:, 0], centred[:, 2] - centred[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1), tol.tiny)[:, None]
    return e1, np.cross(n, e1)


def _planar_targets(src2: NDArray[np.float64], cur: NDArray[np.float64],
                    scale: NDArray[np.float64]) -> NDArray[np.float64]:
    """Local step: (m, 3, 3) targets s_f R_f (N V_f) for current centred triangles cur.

    Triangles are planar, so the best 3D rotation maps the source plane onto the current
    plane and is a 2D rotation in between. With 2D corner coordinates p (source, src2:
    (m, 3, 2)) and q (current), the 2x2 cross-covariance H = sum_k p_k q_k^T has the
    maximiser of tr(R H) over rotations at angle atan2(H01 - H10, H00 + H11): the SVD
    solution in closed form, with no reflection case.
    """
    e1, e2 = _frames(cur)
    q = np.stack([np.einsum("fki,fi->fk", cur, e1), np.einsum("fki,fi->fk", cur, e2)], axis=2)
    h = np.einsum("fki,fkj->fij", src2, q)
    theta = np.arctan2(h[:, 0, 1] - h[:, 1, 0], h[:, 0, 0] + h[:, 1, 1])
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    px, py = src2[:, :, 0], src2[:, :, 1]
    rx = scale[:, None] * (c * px - s * py)
    ry = scale[:, None] * (s * px + c * py)
    return rx[:, :, None] * e1[:, None, :] + ry[:, :, None] * e2[:, None, :]


def deform_to_constant_width(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                             width: NDArray[np.float64], iterations: int = 30,
                             rtol: float = 1e-4, anderson: int = 5,
                             scale_tol: float = 0.0) -> DeformResult:
    """Deform the layer so that the per-vertex target width becomes constant (eqs. 13, 14).

    vertices: (n, 3) float64 mm; faces: (m, 3) int; width: (n,) float64 mm > 0, target
    toolpath width W(x) per vertex; iterations: maximum local-global iterations; anderson:
    history length of the Anderson acceleration (0 = plain local-global); scale_tol: stop
    once the achieved scale is within this of the target (relative) on 90 % of the area
    (0: iterate until the energy converges or ``iterations`` run out). Faces are
    weighted by their area (a discretisation-independent form of eq. 13). One vertex per
    component is pinned during the solve and each component is translated back to its
    input centroid.
    """
    check_mesh(vertices, faces)
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    w = np.asarray(width, dtype=np.float64)
    if w.shape != (len(v),) or not np.all(np.isfinite(w)) or w[np.unique(f)].min() <= 0:
        raise InputError("deformation needs one positive finite width per vertex (mm)",
                         "compute W = C / (H f(H / beta)) for every layer vertex")
    if iterations < 1:
        raise InputError(f"iterations must be >= 1, got {iterations}", "use e.g. 10")
    if not 0.0 <= scale_tol < 1.0:
        raise InputError(f"scale_tol must be in [0, 1), got {scale_tol}", "use e.g. 0.01")
    n, m = len(v), len(f)
    used = np.unique(f)
    scale = face_scale(v, f, w)
    _, area = face_normals(v, f)
    wt = np.sqrt(area / max(area.mean(), tol.tiny))
    # A: (3m, n) rows x_k - mean(x_f) weighted by sqrt(area); K = A^T A depends on topology only
    rows = np.repeat(np.arange(3 * m), 3)
    cols = np.repeat(f, 3, axis=0).reshape(-1)
    corner = np.tile(np.arange(3), 3 * m)
    own = np.repeat(np.tile(np.arange(3), m), 3)
    vals = (np.where(corner == own, 2.0 / 3.0, -1.0 / 3.0) * np.repeat(wt, 9))
    a = sp.csr_matrix((vals, (rows, cols)), shape=(3 * m, n))
    k_full = (a.T @ a).tocsc()
    # one pinned vertex per edge-connected component removes the translations
    pin = np.array([f[c[0], 0] for c in components(f)], dtype=np.int64)
    free = np.setdiff1d(used, pin)
    k_free = k_full[free]
    solve = spd_solver(k_free[:, free])
    k_pin = k_free[:, pin]
    a_t = a.T.tocsr()

    centred = v[f] - v[f].mean(axis=1, keepdims=True)  # (m, 3, 3), N V_f
    s1, s2 = _frames(centred)
    src2 = np.stack([np.einsum("fki,fi->fk", centred, s1),
                     np.einsum("fki,fi->fk", centred, s2)], axis=2)  # (m, 3, 2) in-plane
    wt3 = np.repeat(wt, 3)[:, None]

    def local(x: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
        """Optimal targets for x and the energy of eq. 13 at x (area-weighted, mm^2)."""
        cur = x[f] - x[f].mean(axis=1, keepdims=True)
        target = _planar_targets(src2, cur, scale)
        return target, float((area[:, None, None] * (cur - target) ** 2).sum())

    def global_step(target: NDArray[np.float64], x: NDArray[np.float64]) -> NDArray[np.float64]:
        rhs = a_t @ (target.reshape(-1, 3) * wt3)
        out = x.copy()
        out[free] = solve(np.asarray(rhs[free] - k_pin @ x[pin]))
        return out

    x = v.copy()
    target, energy = local(x)
    trace: list[float] = []
    status = DeformStatus.MAX_ITERATIONS
    # energy that counts as zero: relative to the size of the layer in the same units
    floor = 1e-20 * float((area[:, None, None] * centred**2).sum())
    # Anderson acceleration of the local-global fixed point x -> G(x) (plain local-global
    # needs hundreds of iterations when the scale field forces the layer to bend); a step
    # that raises the energy is replaced by the plain step, so the trace never increases
    hist_g: list[NDArray[np.float64]] = []
    hist_f: list[NDArray[np.float64]] = []
    g_prev: NDArray[np.float64] | None = None
    f_prev: NDArray[np.float64] | None = None
    # without a tolerance the deviation is only reported, not checked every iteration
    deviation = scale_deviation(x, f, area, scale)[0] if scale_tol > 0 else np.inf
    for _ in range(iterations):
        if energy <= floor:
            status = DeformStatus.CONVERGED
            break
        if deviation <= scale_tol:
            status = DeformStatus.WITHIN_TOLERANCE
            break
        g = global_step(target, x)
        res = (g - x)[free].ravel()
        if g_prev is not None and f_prev is not None:
            hist_g.append((g - g_prev)[free].ravel())
            hist_f.append(res - f_prev)
            if len(hist_g) > anderson:
                hist_g.pop(0)
                hist_f.pop(0)
        g_prev, f_prev = g, res
        cand = g
        if hist_f:
            df = np.stack(hist_f, axis=1)
            gamma = np.linalg.lstsq(df, res, rcond=None)[0]
            cand = g.copy()
            cand[free] = (g[free].ravel() - np.stack(hist_g, axis=1) @ gamma).reshape(-1, 3)
        cand_target, cand_energy = local(cand)
        if cand is not g and not cand_energy <= energy:
            cand_target, cand_energy = local(g)
            cand = g  # keep the history: later extrapolations usually succeed
        previous = energy
        x, target, energy = cand, cand_target, cand_energy
        trace.append(energy)
        if scale_tol > 0:
            deviation = scale_deviation(x, f, area, scale)[0]
        if deviation <= scale_tol:
            status = DeformStatus.WITHIN_TOLERANCE
            break
        if energy <= floor or abs(previous - energy) <= rtol * max(previous, tol.tiny):
            status = DeformStatus.CONVERGED
            break
    for comp in components(f):  # each piece moves back to its own centroid
        ids = np.unique(f[comp])
        x[ids] += v[ids].mean(axis=0) - x[ids].mean(axis=0)
    deviation, achieved = scale_deviation(x, f, area, scale)
    return DeformResult(vertices=x, scale=scale, achieved=achieved, status=status,
                        trace=np.asarray(trace), deviation=deviation)
