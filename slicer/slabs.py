"""Slabs of the slicing field: their exact volumes, and layer heights that match them.

Layer k is the middle of the field slab [b_k, b_k+1] (``layers.slab_bounds``); its height per
vertex is H = (b_k+1 - b_k) / |grad g| at the layer, a first-order estimate of the slab's
physical thickness, which is off where |grad g| changes across the slab (so the layer would
get more or less ink than its slab holds). ``slab_height_scale`` gives the factor per layer
that makes the integral of H equal the exact slab volume; the layers stage applies it
(``layers.extract_layers``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from core.tolerance import tol

SCALE_LIMITS = (0.5, 1.5)  # a layer whose H misses its slab by more is left at the limit


def height_integral(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                    face_layer: NDArray[np.integer], height: NDArray[np.float64],
                    n_layers: int) -> NDArray[np.float64]:
    """(L,) float64, mm^3, the integral of H over each layer: sum of area x mean corner H
    (also the toolpath's required volume of a component, ``toolpath.volume.required_volume``)."""
    tri = vertices[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    out: NDArray[np.float64] = np.bincount(face_layer, weights=area * height[faces].mean(axis=1),
                                           minlength=n_layers)[:n_layers].astype(np.float64)
    return out


def slab_height_scale(integral: NDArray[np.float64], slab: NDArray[np.float64]
                      ) -> NDArray[np.float64]:
    """(L,) float64, slab / integral per layer, within SCALE_LIMITS (1 where either is 0).

    Args:
        integral: (L,) mm^3, the integral of H over each layer (``height_integral``).
        slab: (L,) mm^3, the exact volume of each layer's slab (``slab_volumes``).
    """
    ok = (integral > 0) & (slab > 0)
    ratio = np.divide(slab, integral, out=np.ones_like(integral), where=ok)
    return np.clip(ratio, *SCALE_LIMITS)


def slab_volumes(vertices: NDArray[np.float64], tets: NDArray[np.integer],
                 g: NDArray[np.float64], bounds: NDArray[np.float64]) -> NDArray[np.float64]:
    """Exact volume of the solid between consecutive field values, mm^3.

    The field g is linear in each tet, so the volume of {x in tet : g(x) <= t} is a
    piecewise cubic in t: with the tet's vertex values g_0..g_3 it is
    vol * sum_i (t - g_i)_+^3 / prod_{j != i} (g_j - g_i) (the divided difference of the
    truncated cube), summed over the vertices on the side of t with fewer of them (1 minus
    the mirrored sum above t). Equal values are split apart by a relative 1e-8 of the tet's
    range; at most two of them then fall on the summed side (nudge and cancellation cost about
    1e-8 relative).

    Args:
        vertices: (V, 3) float64, mm, tet mesh vertices.
        tets: (T, 4) int, vertex indices.
        g: (V,) float64, the slicing field.
        bounds: (S + 1,) float64, increasing field values.

    Returns:
        (S,) float64, mm^3, the volume with bounds[k] <= g < bounds[k + 1].
    """
    b = np.asarray(bounds, dtype=np.float64)
    t_idx = np.asarray(tets, dtype=np.int64)
    p = vertices[t_idx]
    e1, e2, e3 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    vol = np.abs(np.einsum("ij,ij->i", e1, np.cross(e2, e3))) / 6.0
    gv = np.sort(g[t_idx], axis=1)
    span = gv[:, 3] - gv[:, 0]
    # distinct values: nudge ties apart (their order is kept, so the nudge only grows gaps)
    eps = 1e-8 * np.maximum(span, tol.zero)
    gv = gv + eps[:, None] * np.arange(4.0)
    # volume below each bound: whole tets under it plus the fraction of tets it cuts
    below = np.zeros(len(b))
    order = np.argsort(gv[:, 3], kind="stable")
    cum = np.concatenate([[0.0], np.cumsum(vol[order])])
    below += cum[np.searchsorted(gv[order, 3], b, side="right")]
    first = np.searchsorted(b, gv[:, 0], side="right")
    last = np.searchsorted(b, gv[:, 3], side="left")  # bounds strictly inside (g0, g3)
    count = np.maximum(last - first, 0)
    tet = np.repeat(np.arange(len(gv)), count)
    k = np.repeat(first, count) + (np.arange(count.sum())
                                   - np.repeat(np.cumsum(count) - count, count))
    t = b[k][:, None]
    gt = gv[tet]
    diff = gt[:, None, :] - gt[:, :, None]  # [i, j] = g_j - g_i
    diff[:, np.arange(4), np.arange(4)] = 1.0
    prod = diff.prod(axis=2)  # prod_{j != i} (g_j - g_i); the sign flips with 3 factors
    lower = (np.maximum(t - gt, 0.0) ** 3 / prod).sum(axis=1)
    upper = 1.0 + (np.maximum(gt - t, 0.0) ** 3 / prod).sum(axis=1)
    # sum over the side of t with fewer values: a tie of three on the other side would
    # cancel terms of size 1 / nudge^2
    frac = np.where((gt < t).sum(axis=1) <= 2, lower, upper)
    np.add.at(below, k, vol[tet] * np.clip(frac, 0.0, 1.0))
    return np.diff(below)
