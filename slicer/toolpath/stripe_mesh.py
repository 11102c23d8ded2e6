"""The layer split finely enough for the stripe field to resolve its period.

The stripe field (``stripes.stripe_field``) is linear in each face: where a face is about as
wide as the stripe spacing (the bundled hemisphere's layers: edges 0.6-1.0 spacing) the phase
turns by pi or more per edge, and the crests interpolated across the faces lie off the middle
of their neighbours by up to a third of their gaps. ``fine_mesh`` splits the layer at its edge
midpoints (1 to 4, twice at most) until its median edge is at most FINE_EDGE x spacing; the
lines found there go back onto the layer's own faces with ``on_parent`` (a split face lies in
its parent's plane, so the points do not move). Measured effect: docs/benchmarks.md
("Session 21: stripes").
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slicer.toolpath.layer_nearest import inside_barycentric
from slicer.toolpath.lines import SurfaceLines

FINE_EDGE = 0.5  # x spacing: the field is solved on edges at most this long (median; the
# phase then turns at most pi per edge, two samples a period) ...
FINE_LEVELS = 2  # ... splitting the layer at most this many times


def fine_mesh(vertices: NDArray[np.float64], faces: NDArray[np.int64], spacing: float
              ) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    """The layer split (midpoints, 1 to 4) until its median edge is at most FINE_EDGE x
    ``spacing`` (at most FINE_LEVELS times): vertices (n', 3) mm, faces (m', 3) and each
    new face's face of the given mesh (m',). The new vertices lie in their parent's plane."""
    v, f = np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)
    parent = np.arange(len(f))
    for _ in range(FINE_LEVELS):  # a level or two
        edge = np.linalg.norm(v[f] - v[np.roll(f, 1, axis=1)], axis=2)
        if len(f) == 0 or float(np.median(edge)) <= FINE_EDGE * spacing:
            break
        v, f, owner = _split(v, f)
        parent = parent[owner]
    return v, f, parent


def _split(v: NDArray[np.float64], f: NDArray[np.int64]
           ) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    """Each face split into four at its edge midpoints (shared by the faces of an edge):
    vertices (n + E, 3), faces (4 m, 3) in the parent's winding, and each face's parent."""
    m = len(f)
    edge = np.sort(np.stack([f, np.roll(f, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    unique, inverse = np.unique(edge, axis=0, return_inverse=True)
    mid = len(v) + inverse.reshape(m, 3)  # midpoint of side k (corner k -> k + 1)
    v = np.concatenate([v, 0.5 * (v[unique[:, 0]] + v[unique[:, 1]])])
    a, b, c = f[:, 0], f[:, 1], f[:, 2]
    ab, bc, ca = mid[:, 0], mid[:, 1], mid[:, 2]
    f = np.stack([np.column_stack([a, ab, ca]), np.column_stack([ab, b, bc]),
                  np.column_stack([ca, bc, c]), np.column_stack([ab, bc, ca])],
                 axis=1).reshape(-1, 3)
    return v, f, np.repeat(np.arange(m), 4)


def on_parent(lines: SurfaceLines, vertices: NDArray[np.float64], faces: NDArray[np.int64],
               parent: NDArray[np.int64]) -> SurfaceLines:
    """Lines found on ``fine_mesh`` put on the mesh it split (faces and barycentrics)."""
    if len(parent) == len(faces):  # not split: the lines are already on the layer
        return lines
    face = parent[lines.face].astype(np.int32)
    bary = inside_barycentric(lines.points, vertices, faces.astype(np.int32), face)
    points = np.einsum("pk,pkj->pj", bary, vertices[faces[face]])
    return SurfaceLines(points=points, face=face, bary=bary, line=lines.line,
                        closed=lines.closed)
