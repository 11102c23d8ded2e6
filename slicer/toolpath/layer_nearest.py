"""The layer point nearest to a point in space, with its face and barycentrics.

Points added to a toolpath off its lines (a spiral's blend, a tip's line, a stripe join's
taper) must lie on the layer, with the face and barycentrics every waypoint carries
(mapback, eq. 15). The nearest point is searched among the ``k`` faces whose centroids are
nearest (a KD-tree the caller may keep across calls): exact where the layer's faces are
small against their distance, which holds for points already on or beside the layer.
"""

from __future__ import annotations

import numpy as np
import trimesh
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from core.tolerance import tol
from slicer.toolpath.mapback import barycentric


def face_tree(vertices: NDArray[np.float64], faces: NDArray[np.int64 | np.int32]) -> cKDTree:
    """The KD-tree of the face centroids ((m, 3) mm) that ``nearest_on_layer`` searches."""
    return cKDTree(vertices[faces].mean(axis=1))


def nearest_on_layer(points: NDArray[np.float64], vertices: NDArray[np.float64],
                     faces: NDArray[np.int64 | np.int32], k: int,
                     tree: cKDTree | None = None
                     ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The nearest layer point to each of ``points`` ((P, 3) mm) among its ``k`` faces with
    the nearest centroids: (P, 3) mm and the face (P,) int64. ``tree``: ``face_tree`` of the
    same layer, or None to build it. A degenerate face (marching tets) is never chosen."""
    tri = vertices[faces]
    k = min(k, len(faces))
    _, cand = (face_tree(vertices, faces) if tree is None else tree).query(points, k=k)
    cand = np.asarray(cand, dtype=np.int64).reshape(len(points), k)
    rep = np.repeat(points, k, axis=0)
    closest = trimesh.triangles.closest_point(tri[cand.ravel()], rep)
    d = np.linalg.norm(closest - rep, axis=1).reshape(len(points), k)
    best = np.argmin(np.where(np.isfinite(d), d, np.inf), axis=1)
    rows = np.arange(len(points))
    return closest.reshape(len(points), k, 3)[rows, best], cand[rows, best]


def inside_barycentric(points: NDArray[np.float64], vertices: NDArray[np.float64],
                       faces: NDArray[np.int32], face: NDArray[np.int32]
                       ) -> NDArray[np.float64]:
    """Barycentrics (P, 3) of ``points`` on ``face`` (``mapback.barycentric``), clipped to
    the face and summing to 1 (a point on an edge may come out a hair outside)."""
    bary = np.clip(barycentric(points, vertices, faces, face), 0.0, None)
    return bary / np.maximum(bary.sum(axis=1, keepdims=True), tol.zero)
