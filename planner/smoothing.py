"""Normals smoothed along their path where they turn fast, by a bounded angle.

Where the normal turns sharply along a path, following it exactly makes the long tool swing
the arm and forces the TCP slower than the toolpath speed; a small, bounded deviation from
-normal (at most ``smooth_max_deg`` of the cell's planning section) keeps the speed.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy import ndimage

from core.stages import Toolpath
from planner.orientation import unit
from planner.upright import turn_towards

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
