"""One line across a layer component too small for any line of its pattern: a tip.

A layer that only grazes the top of a rounded feature (the knob of a lid, a finger tip, the
top of a dome) cuts it in a small disc, about one width across: eq. 9's ring inside it is
shorter than the shortest path, a stripe shorter than its trimmed ends, and a disc has no
medial line, so the component would print nothing (all of its volume left out: the teapot's
lid knob, two layers). It gets one line instead: the chord through its area centroid along
its longest principal axis, on the surface, its ends pulled in by TIP_INSET of the chord (at
most W / 2) so the filament's rounded ends stay on the component. Its width then follows
from the volume (the caller's flow fit, within the narrowest and widest filament).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from core.tolerance import tol
from slicer.toolpath.layer_nearest import inside_barycentric, nearest_on_layer
from slicer.toolpath.lines import SurfaceLines, empty_lines

TIP_INSET = 0.1  # each end of the chord pulled in by this share of it (at most W / 2): the
# line's band over a disc D across is then about D wide (0.2: 1.3 D, spilling over its sides)
TIP_POINTS = 41  # points sampled along the chord
NEAREST_FACES = 16  # candidate faces per point for its foot on the surface
ON_SURFACE = 0.05  # a chord point whose foot lies farther than this x the chord is off it


def tip_line(vertices: NDArray[np.float64], faces: NDArray[np.int32], width: float
             ) -> SurfaceLines:
    """The one line of a tip component (module docstring), or no line.

    vertices: (n, 3) float64 mm; faces: (m, 3) int32, one component; width: W, mm.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return empty_lines()
    tri = v[f]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    if area.sum() <= tol.zero:
        return empty_lines()
    centre = tri.mean(axis=1)
    c = (area[:, None] * centre).sum(axis=0) / area.sum()
    d = v[np.unique(f)] - c
    axis = np.linalg.eigh(d.T @ d)[1][:, -1]  # the longest principal axis
    t = d @ axis
    reach = np.linspace(float(t.min()), float(t.max()), TIP_POINTS)
    target = c + reach[:, None] * axis
    foot, face = nearest_on_layer(target, v, f, NEAREST_FACES, cKDTree(centre))
    chord = float(t.max() - t.min())
    on = np.linalg.norm(foot - target, axis=1) <= ON_SURFACE * max(chord, tol.zero)
    # the run of points on the surface around the centroid (a bent tip: one side)
    mid = int(np.argmin(np.abs(reach)))
    if not on[mid]:
        return empty_lines()
    lo = mid - int(np.argmin(on[mid::-1])) + 1 if not on[: mid + 1].all() else 0
    hi = mid + int(np.argmin(on[mid:])) if not on[mid:].all() else len(on)
    span = reach[hi - 1] - reach[lo]
    inset = min(TIP_INSET * span, 0.5 * width)
    keep = np.arange(lo, hi)
    keep = keep[(reach[keep] >= reach[lo] + inset) & (reach[keep] <= reach[hi - 1] - inset)]
    if len(keep) < 2:
        return empty_lines()
    bary = inside_barycentric(foot[keep], v, f.astype(np.int32), face[keep].astype(np.int32))
    return SurfaceLines(points=foot[keep], face=face[keep].astype(np.int32), bary=bary,
                        line=np.zeros(len(keep), dtype=np.int32),
                        closed=np.zeros(1, dtype=bool))
