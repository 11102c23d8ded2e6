"""Derivatives along the sampled path: one-sided at junctions, and over a window of arc length.

A junction is a sample where deposition stops or starts: on one side a depositing step, on
the other a move between paths, whose nozzle turns at rates that have nothing to do with the
depositing steps; the joint path has a kink there. Central differences and a curvature window
reaching across it smear the move's rates onto the depositing samples next to it, and the
time law then slows those. Here rates at a junction come from its depositing side alone, and
a window does not reach across one; the time law's discrete acceleration check of the step
beside it still holds the kink to the joints' limits.
"""

from __future__ import annotations

import numpy as np

from core.tolerance import tol


def junctions(extrude: np.ndarray) -> np.ndarray:
    """(M,) int8 of ``extrude`` (M,) bool: -1 where deposition stops (the arriving step
    deposits, the leaving one does not), +1 where it starts, 0 elsewhere."""
    ex = np.asarray(extrude, dtype=bool)
    side = np.zeros(len(ex), dtype=np.int8)
    if len(ex) > 1:
        side[1:][ex[:-1] & ~ex[1:]] = -1
        side[1:][~ex[:-1] & ex[1:]] = 1
    return side


def neighbours(M: int, side: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(next, previous) sample (M,), (M,) of each difference: central, one-sided at the ends
    and where ``side`` says (-1 the arriving step, +1 the leaving one)."""
    k = np.arange(M)
    nxt = np.minimum(k + 1, M - 1)
    prv = np.maximum(k - 1, 0)
    if side is not None:
        nxt = np.where(side < 0, k, nxt)
        prv = np.where(side > 0, k, prv)
    return nxt, prv


def window_derivative(y: np.ndarray, s: np.ndarray, h: float,
                      side: np.ndarray | None = None) -> np.ndarray:
    """d y / d s (M, k) as the difference over [s - h, s + h] (clipped to the path's ends,
    and to the junctions of ``side``: a window does not reach across one).

    Args:
        y: (M, k) float64, values at the samples. s: (M,) float64, increasing.
        h: float, half window in units of ``s``; 0 gives ``np.gradient``.
        side: (M,) int8 or None, ``junctions``: a junction's own window lies on its -1
            (arriving) or +1 (leaving) side.
    """
    if h <= 0 or len(s) < 2:
        return np.gradient(y, s, axis=0) if len(s) > 1 else np.zeros_like(y)
    lo = np.maximum(s - h, s[0])
    hi = np.minimum(s + h, s[-1])
    if side is not None and np.any(side != 0):
        k = np.arange(len(s))
        # the last junction at or before each sample (itself only if it leaves: +1), and the
        # first at or after it (itself only if it arrives: -1)
        prev_cut = np.maximum.accumulate(np.where(side != 0, k, -1))
        prev_cut = np.where(side < 0, np.r_[-1, prev_cut[:-1]], prev_cut)
        next_cut = np.minimum.accumulate(np.where(side != 0, k, len(s))[::-1])[::-1]
        next_cut = np.where(side > 0, np.r_[next_cut[1:], len(s)], next_cut)
        lo = np.where(prev_cut >= 0, np.maximum(lo, s[np.maximum(prev_cut, 0)]), lo)
        hi = np.where(next_cut < len(s), np.minimum(hi, s[np.minimum(next_cut, len(s) - 1)]),
                      hi)
    span = np.maximum(hi - lo, tol.zero)
    out = np.empty_like(y)
    for j in range(y.shape[1]):  # a loop over the columns (six joints), not the samples
        out[:, j] = (np.interp(hi, s, y[:, j]) - np.interp(lo, s, y[:, j])) / span
    return out
