"""Uniform refinement of a tet mesh, with its new boundary vertices snapped to the surface.

fTetWild's time grows much faster than its output: on the socket it takes ~170 s for 240k
tets at a 2.95 mm target and ~28 s for 29k tets at 5.9 mm. One red refinement (Bey 1995:
every tet into 8, the 4 corner tets similar to it and the inner octahedron cut along its
shortest diagonal) turns the second into 232k tets in half a second, with the same shape
quality. Its new vertices on the boundary are edge midpoints, which lie on the coarse mesh's
chords rather than on the model's surface; ``snap_boundary`` moves them onto the input
surface (the closest point, libigl), backing off wherever that would flatten or invert a tet,
so the refined mesh follows the model as closely as one meshed directly at the fine size.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from slicer.operators import TET_FACES
from slicer.tet_geometry import orient_positive, tet_volumes

_PAIRS = np.array([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)])
# The inner octahedron's three diagonals (pairs of opposite edge midpoints, as indices into
# m01, m02, m03, m12, m13, m23) and, for each, its other four vertices in cyclic order.
_DIAGONALS = ((0, 5), (1, 4), (2, 3))
_RINGS = ((1, 2, 4, 3), (0, 2, 5, 3), (0, 1, 5, 4))
# A snapped tet must keep at least this share of its volume before the snap.
KEEP_VOLUME = 0.7
# Halvings of a vertex's snap displacement before it is given up.
BACKOFFS = 6


class Snap(NamedTuple):
    """Result of ``snap_boundary``.

    vertices: (V, 3) float64, mm, with the snapped boundary vertices moved.
    moved_mm: (n,) float64, mm, how far each candidate vertex moved (0 where it backed off).
    backed_off: number of candidates that moved less than their full distance.
    """

    vertices: NDArray[np.float64]
    moved_mm: NDArray[np.float64]
    backed_off: int


def red_refine(vertices: NDArray[np.float64], tets: NDArray[np.integer]
               ) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
    """Every tet into 8 (Bey's red refinement, shortest inner diagonal).

    Args:
        vertices: (V, 3) float64, mm.
        tets: (T, 4) int, vertex indices.

    Returns:
        (V + E, 3) float64 mm, the old vertices then one midpoint per unique edge, and
        (8 T, 4) int32 positively oriented tets. Volumes add up exactly.
    """
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(tets, dtype=np.int64)
    edges = np.sort(t[:, _PAIRS], axis=2).reshape(-1, 2)
    unique, inverse = np.unique(edges, axis=0, return_inverse=True)
    out_v = np.vstack([v, 0.5 * (v[unique[:, 0]] + v[unique[:, 1]])])
    m = len(v) + inverse.reshape(-1, 6)  # (T, 6): m01, m02, m03, m12, m13, m23
    m01, m02, m03, m12, m13, m23 = m.T
    v0, v1, v2, v3 = t.T
    corners = [np.stack(c, axis=1) for c in ((v0, m01, m02, m03), (m01, v1, m12, m13),
                                            (m02, m12, v2, m23), (m03, m13, m23, v3))]
    lengths = np.stack([np.linalg.norm(out_v[m[:, a]] - out_v[m[:, b]], axis=1)
                        for a, b in _DIAGONALS], axis=1)
    pick = np.argmin(lengths, axis=1)  # (T,) which diagonal
    rows = np.arange(len(t))
    a = m[rows, np.take(np.array(_DIAGONALS)[:, 0], pick)]
    b = m[rows, np.take(np.array(_DIAGONALS)[:, 1], pick)]
    ring = m[rows[:, None], np.array(_RINGS)[pick]]  # (T, 4)
    inner = [np.stack([a, b, ring[:, k], ring[:, (k + 1) % 4]], axis=1) for k in range(4)]
    out_t = np.vstack(corners + inner).astype(np.int32)
    return out_v, orient_positive(out_v, out_t)


def boundary_vertices(tets: NDArray[np.integer]) -> NDArray[np.int64]:
    """(n,) int64, sorted ids of the vertices on the boundary faces of a tet mesh."""
    faces = np.sort(np.asarray(tets, dtype=np.int64)[:, TET_FACES].reshape(-1, 3), axis=1)
    unique, counts = np.unique(faces, axis=0, return_counts=True)
    return np.unique(unique[counts == 1])


def snap_boundary(vertices: NDArray[np.float64], tets: NDArray[np.integer],
                  candidates: NDArray[np.integer], surface_vertices: NDArray[np.float64],
                  surface_faces: NDArray[np.integer]) -> Snap:
    """Move ``candidates`` (boundary vertex ids) to their closest points on a surface.

    A vertex whose move would leave one of its tets with less than ``KEEP_VOLUME`` of its
    volume moves half as far, up to ``BACKOFFS`` times, then not at all: no tet inverts.

    Args:
        vertices: (V, 3) float64, mm. tets: (T, 4) int, positively oriented.
        candidates: (n,) int, vertex ids to snap.
        surface_vertices: (S, 3) float64, mm; surface_faces: (F, 3) int, the input surface.
    """
    import igl

    v = np.asarray(vertices, dtype=np.float64)
    ids = np.asarray(candidates, dtype=np.int64)
    if len(ids) == 0:
        return Snap(v.copy(), np.zeros(0), 0)
    _, _, closest = igl.point_mesh_squared_distance(
        v[ids], np.asarray(surface_vertices, dtype=np.float64),
        np.asarray(surface_faces, dtype=np.int64))
    step = np.asarray(closest) - v[ids]
    t = np.asarray(tets, dtype=np.int64)
    slot = np.full(len(v), -1, dtype=np.int64)
    slot[ids] = np.arange(len(ids))
    touched = np.flatnonzero((slot[t] >= 0).any(axis=1))  # only these tets can change
    tt = t[touched]
    before = tet_volumes(v, tt)
    scale = np.ones(len(ids))
    out = v.copy()
    for attempt in range(BACKOFFS + 2):
        out[ids] = v[ids] + scale[:, None] * step
        bad = tet_volumes(out, tt) < KEEP_VOLUME * before
        if not bad.any():
            break
        culprits = slot[tt[bad]]
        culprits = np.unique(culprits[culprits >= 0])
        # halve the moves of the vertices of every flattened tet; the last time, undo them
        # (a tet whose moved vertices all stay is its old self, so this ends)
        scale[culprits] = 0.5 * scale[culprits] if attempt < BACKOFFS else 0.0
    while bad.any():
        out[ids] = v[ids] + scale[:, None] * step
        bad = tet_volumes(out, tt) < KEEP_VOLUME * before
        culprits = slot[tt[bad]]
        scale[culprits[culprits >= 0]] = 0.0
    moved = scale * np.linalg.norm(step, axis=1)
    return Snap(out, moved, int(np.count_nonzero(scale < 1.0)))
