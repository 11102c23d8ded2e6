"""Isolated normal spikes of a toolpath replaced by their neighbours' mean.

The layer meshes occasionally hold a degenerate triangle whose normal stands tens of degrees
off its neighbours'; a toolpath waypoint on it carries that normal, and a nozzle following it
would swing the wrist within a fraction of a millimetre of path.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from core.stages import Toolpath
from core.tolerance import tol


def _unit(v: np.ndarray) -> np.ndarray:
    """Rows of ``v`` (..., 3) normalised (zero rows stay zero)."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > tol.zero, n, 1.0)


def repair_normals(toolpath: Toolpath, spike_deg: float = 20.0,
                   agree_deg: float = 10.0) -> tuple[Toolpath, np.ndarray]:
    """Replace isolated normal spikes (one or two waypoints) by their neighbours' mean.

    A waypoint's normal is a spike when it deviates more than ``spike_deg`` from the mean of
    the normals ``gap`` waypoints before and after it (gap 1, then 2, within one path) while
    those two agree within ``agree_deg``. The slicer occasionally yields such spikes (a
    degenerate layer triangle); following one would swing the wrist tens of degrees within
    a fraction of a millimetre of path. Returns the repaired toolpath and the (N,) bool mask
    of repaired waypoints.
    """
    n = np.array(toolpath.normal, dtype=float)
    path = toolpath.path
    N = len(n)
    done = np.zeros(N, dtype=bool)
    for gap in (1, 2):
        if N <= 2 * gap:
            break
        i = np.arange(gap, N - gap)
        prv, nxt = i - gap, i + gap
        same = (path[prv] == path[i]) & (path[nxt] == path[i])
        m = _unit(n[prv] + n[nxt])
        agree = np.einsum("ij,ij->i", n[prv], n[nxt]) >= np.cos(np.radians(agree_deg))
        spike = np.einsum("ij,ij->i", n[i], m) < np.cos(np.radians(spike_deg))
        fix = i[same & agree & spike]
        n[fix] = m[same & agree & spike]
        done[fix] = True
    if not done.any():
        return toolpath, done
    return replace(toolpath, normal=n), done
