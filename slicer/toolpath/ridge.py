"""The ridge line inside the innermost contour ring: what covers the centre it leaves bare.

The innermost ring of eq. 9 stops short of the boundary distance's peak by up to a ring
spacing, leaving a bare spot (a round ring) or strip (an elongated one, around the ridge of
the distance) inside it. ``ridge_line`` finds, in the plane of the ring's two principal axes,
the point inside the ring farthest from it (half-width h) and the parallel to the long axis
through it: a line along it, h short of the ring's extent each way and on past that by the
bare width rho = h - W / 2, covers the strip with its W-wide band and stops where the ring's
band begins.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from core.tolerance import tol

CENTRE_BARE = 0.4  # a line only where the bare strip is wider than this x W (radius): the
# line covers about pi rho^2 and lies over about W^2 / 2 of the ring's band where it leaves it
RIDGE_CLEAR = 0.75  # ... and along the ridge while at least this x W from the ring
RIDGE_GRID = (25, 11)  # points along x across the ring searched for its deepest point


def ridge_line(ring: NDArray[np.float64], width: float, start: NDArray[np.float64],
               force: bool = False) -> NDArray[np.float64] | None:
    """(k, 3) mm, points from ``start`` to and along the ridge of ``ring``, or None.

    ring: (n, 3) mm, the ring's points in order (closed); width: W, mm; start: (3,) mm, where
    the nozzle leaves the ring. None where the bare strip is at most CENTRE_BARE x W wide
    (``force``: at most 0, the ring's thin inner loop is left out for the line), or the ridge
    comes within RIDGE_CLEAR x W of the ring at the deepest point. The line ends sooner where
    it would come that close (a tapering end, a ring that is not convex). The points are in
    the ring's principal plane: project them onto a curved layer.
    """
    pts = np.asarray(ring, dtype=np.float64)
    w = float(width)
    step = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    origin = pts.mean(axis=0)
    frame = np.linalg.svd(pts - origin, full_matrices=False)[2][:2]
    uv = (pts - origin) @ frame.T
    u, v = np.meshgrid(np.linspace(uv[:, 0].min(), uv[:, 0].max(), RIDGE_GRID[0]),
                       np.linspace(uv[:, 1].min(), uv[:, 1].max(), RIDGE_GRID[1]))
    cand = np.column_stack([u.ravel(), v.ravel()])
    tree = cKDTree(uv)
    depth = np.where(inside_polygon(cand, uv), tree.query(cand)[0], 0.0)
    best = int(np.argmax(depth))
    half = float(depth[best])
    rho = half - 0.5 * w
    if rho <= (0.0 if force else CENTRE_BARE * w):
        return None
    mid, side = cand[best]
    lo = min(uv[:, 0].min() + half, mid) - rho
    hi = max(uv[:, 0].max() - half, mid) + rho
    spacing = max(float(np.median(step)), tol.merge)
    along = np.linspace(lo, hi, max(int(np.ceil((hi - lo) / spacing)), 1) + 1)
    ridge = np.column_stack([along, np.full(len(along), side)])
    # the run of the ridge around the deepest point that keeps RIDGE_CLEAR x W from the ring
    clear = tree.query(ridge)[0] >= RIDGE_CLEAR * w
    at = int(np.argmin(np.abs(along - mid)))
    if not clear[at]:
        return None
    breaks = np.flatnonzero(~clear)
    first = int(breaks[breaks < at].max()) + 1 if np.any(breaks < at) else 0
    last = int(breaks[breaks > at].min()) if np.any(breaks > at) else len(ridge)
    if last - first < 2:
        return None
    ridge3 = origin + ridge[first:last] @ frame
    p0 = np.asarray(start, dtype=np.float64)
    if np.linalg.norm(ridge3[-1] - p0) < np.linalg.norm(ridge3[0] - p0):
        ridge3 = ridge3[::-1]
    m = max(int(np.ceil(float(np.linalg.norm(ridge3[0] - p0)) / spacing)), 1)
    lead = p0 + ((np.arange(m) + 1.0) / m)[:, None] * (ridge3[0] - p0)
    return np.concatenate([lead, ridge3[1:]])


def inside_polygon(points: NDArray[np.float64], polygon: NDArray[np.float64]) -> NDArray[np.bool_]:
    """(k,) bool, which of ``points`` ((k, 2)) lie inside the closed ``polygon`` ((n, 2),
    its last point joined to its first): matplotlib's point-in-polygon test."""
    from matplotlib.path import Path

    return np.asarray(Path(polygon, closed=False).contains_points(points), dtype=bool)
