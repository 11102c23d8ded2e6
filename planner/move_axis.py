"""The printing direction on a move between paths, eased from one path's end to the next's start.

Why: a move deposits nothing, so its nozzle axis need not follow the layer; but the slicer's
move waypoints carry their layer normals, and the normals are smoothed per path, so the
first step of a move (the lift off the last depositing waypoint) can turn the axis by 20 deg
in under a millimetre. The 460 mm tool turns the joints with it, and where the direction of
the joints' motion jumps at a path's end, the time law must slow the nozzle on the last
depositing steps (and on the first ones after the move). Here the direction on every sample
strictly between the last depositing sample of a path and the first of the next is the
spherical interpolation of those two directions, with the smootherstep
e(u) = 6u^5 - 15u^4 + 10u^3 of the arc length fraction u, held for SETTLE_MM at either
end: no turn rate and no turn acceleration where deposition stops and starts, the whole turn
in the middle of the move, where the speed is not the toolpath's. Depositing samples keep
their directions; the orientation stage checks every sample as before (reach, clearance,
alpha where depositing).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from core.tolerance import tol
from planner.nozzle_axis import any_perpendicular, unit
from planner.samples import Samples

# Length at each end of a move over which the direction is held (at most a quarter of the
# move): the joints' turn starts and ends this far from where deposition stops and starts,
# beyond the time law's curvature window (``timing.CURVATURE_WINDOW_MM``), so the arm can be
# back at the toolpath's speed by the first depositing step.
SETTLE_MM = 1.0


def smootherstep(u: np.ndarray) -> np.ndarray:
    """e(u) = 6u^5 - 15u^4 + 10u^3 on [0, 1] (clipped): e' = e'' = 0 at both ends."""
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (u * (6.0 * u - 15.0) + 10.0)


def slerp(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Unit vectors (N, 3) a fraction ``w`` (N,) of the way along the great circle a -> b.

    Opposite a and b turn about any axis perpendicular to a (no direction is preferred).
    """
    cos = np.clip(np.einsum("ni,ni->n", a, b), -1.0, 1.0)
    theta = np.arccos(cos)
    # the direction to turn towards: b's part perpendicular to a
    perp = b - cos[:, None] * a
    n = np.linalg.norm(perp, axis=1)
    perp = np.where((n > tol.floor)[:, None], perp / np.where(n > tol.floor, n, 1.0)[:, None],
                    any_perpendicular(a))
    ang = (w * theta)[:, None]
    return unit(np.cos(ang) * a + np.sin(ang) * perp)


def moves(extrude: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(start, end) index pairs (K,), (K,) of the moves between depositing runs.

    ``start`` is the sample where deposition stops (its arriving step deposits, its leaving
    step does not); ``end`` the next sample whose leaving step deposits. The samples strictly
    between them are the move's.
    """
    ex = np.asarray(extrude, dtype=bool)
    if len(ex) < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    stops = np.flatnonzero(ex[:-1] & ~ex[1:]) + 1  # deposition ends at these samples
    starts = np.flatnonzero(~ex[:-1] & ex[1:]) + 1  # and starts again at these
    if not len(stops) or not len(starts):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    nxt = np.searchsorted(starts, stops, side="left")
    has = nxt < len(starts)
    return stops[has], starts[nxt[has]]


def ease_moves(samples: Samples) -> Samples:
    """``samples`` with the directions on every move eased (see module docstring)."""
    a, b = moves(samples.extrude)
    inside = b - a - 1
    if not len(a) or not inside.sum():
        return samples
    # arc length along the samples
    step = np.linalg.norm(np.diff(samples.tcp, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(step)])
    move = np.repeat(np.arange(len(a)), inside)
    first = np.concatenate([[0], np.cumsum(inside)[:-1]])
    idx = a[move] + 1 + (np.arange(int(inside.sum())) - first[move])
    span = s[b] - s[a]
    # the direction is held over the first and last SETTLE_MM (at most a quarter of the move)
    settle = np.minimum(SETTLE_MM, 0.25 * span)
    turn = span - 2.0 * settle
    # a move of zero length (repeated samples) eases by sample count instead
    by_count = (idx - a[move]) / (b - a)[move]
    frac = np.where(span[move] > tol.still,
                    (s[idx] - s[a][move] - settle[move])
                    / np.where(turn > tol.still, turn, 1.0)[move], by_count)
    normal = samples.normal.copy()
    normal[idx] = slerp(samples.normal[a][move], samples.normal[b][move], smootherstep(frac))
    return replace(samples, normal=normal)
