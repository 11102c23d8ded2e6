"""Distance on a layer surface as the fixed point of the discrete eikonal equation.

The heat method (``slicer.toolpath.geodesic``, paper section 4.2) smooths the distance over
about one edge length (t = h^2). On the coarse layer meshes that marching tetrahedra cut from
a 2-3 mm tet mesh, that shifts the boundary distance by 0.1-0.4 mm near the boundary (a 20 mm
square layer of the cube: mean 0.17 mm, p90 0.39 mm), a sizeable part of a 1.2-2.4 mm line
width, so contours drawn at d = W/2 + k W wander by that much.

This solver gives the distance that is exact wherever the front is straight within each
triangle (a straight boundary, any offset of it, a polygon's corner region): each vertex c of a
triangle (a, b, c) takes the shortest way to the opposite edge, min over the edge point
P(l) = a + l (b - a) of T(P) + |P - c|, with T linear along the edge (the triangle update of
fast marching in its edge-interpolation form; closed form below). Boundary edges have T = 0 at
both ends, so a vertex next to the boundary gets its exact distance to the boundary segment,
not to the nearest boundary vertex. The update is applied to all triangles at once (Jacobi
passes, vectorised), starting from Dijkstra's graph distance, an upper bound; a pass revisits
only the triangles around vertices that changed in the previous one, until nothing changes.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import dijkstra

from slicer.tolerance import tol


class EikonalResult(NamedTuple):
    """Distance from a source set and how the solve went.

    distance: (n,) float64, mm, per vertex (0 on the sources, inf where unreachable).
    passes:   int, Jacobi passes run.
    converged: bool, False when ``max_passes`` stopped it first (the distance is then still an
        upper bound, at least as good as the graph distance).
    """

    distance: NDArray[np.float64]
    passes: int
    converged: bool


def _graph_distance(v: NDArray[np.float64], f: NDArray[np.int64],
                    src: NDArray[np.int64]) -> NDArray[np.float64]:
    """(n,) float64 mm, shortest path along the mesh edges from ``src``."""
    n = len(v)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    w = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
    # a zero-length edge would be dropped as "no edge" by csgraph: keep it connected
    w = np.maximum(w, tol.zero)
    graph = sp.coo_matrix((w, (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    out: NDArray[np.float64] = dijkstra(graph.maximum(graph.T), directed=False, indices=src,
                                        min_only=True)
    return out


def triangle_update(v: NDArray[np.float64], f: NDArray[np.int64], t: NDArray[np.float64]
                    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Candidate distances of each triangle's corners from their opposite edges.

    For corners c of rotations (a, b, c) of ``f`` (m, 3): min over l in [0, 1] of
    t_a + l (t_b - t_a) + |a + l (b - a) - c|, a convex function of l whose stationary
    point is l* = (-p - dt sqrt(|e x d0|^2 / (|e|^2 - dt^2))) / |e|^2 with d0 = a - c,
    e = b - a, p = d0 . e, dt = t_b - t_a (when |dt| >= |e| the minimum is at an end).

    Returns ((3m,) float64 mm candidates, (3m,) int64 the corner each is for).
    """
    cand = []
    ids = []
    for k in range(3):
        a, b, c = f[:, k], f[:, (k + 1) % 3], f[:, (k + 2) % 3]
        d0 = v[a] - v[c]
        e = v[b] - v[a]
        ta, tb = t[a], t[b]
        finite = np.isfinite(ta) & np.isfinite(tb)
        dt = np.where(finite, np.where(finite, tb, 0.0) - np.where(finite, ta, 0.0), 0.0)
        ee = np.einsum("ij,ij->i", e, e)
        p = np.einsum("ij,ij->i", d0, e)
        cross = np.maximum(ee * np.einsum("ij,ij->i", d0, d0) - p * p, 0.0)
        room = ee - dt * dt
        inner = room > tol.zero * np.maximum(ee, tol.zero)
        lam = np.where(inner, (-p - dt * np.sqrt(cross / np.where(inner, room, 1.0)))
                       / np.maximum(ee, tol.zero), np.where(dt > 0.0, 0.0, 1.0))
        lam = np.clip(lam, 0.0, 1.0)
        val = ta + lam * dt + np.linalg.norm(d0 + lam[:, None] * e, axis=1)
        # one corner still unknown (inf): reach c along the edge from the known one
        edge = np.minimum(ta + np.sqrt(np.einsum("ij,ij->i", d0, d0)),
                          tb + np.linalg.norm(v[b] - v[c], axis=1))
        cand.append(np.where(finite, val, edge))
        ids.append(c)
    return np.concatenate(cand), np.concatenate(ids)


def eikonal_distance(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                     sources: NDArray[np.integer], max_passes: int = 2000,
                     tolerance: float = 1e-7) -> EikonalResult:
    """Distance over the surface from the vertex set ``sources`` (module doc).

    vertices: (n, 3) float64 mm; faces: (m, 3) int; sources: vertex ids (d = 0 there; for the
    distance from a boundary, all its vertices, so its edges are sources too).
    tolerance: float, mm, a vertex whose distance falls by less counts as unchanged.
    """
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    n, m = len(v), len(f)
    src = np.unique(np.asarray(sources, dtype=np.int64).ravel())
    if n == 0 or m == 0 or src.size == 0:
        return EikonalResult(np.full(n, np.inf), 0, True)
    t = _graph_distance(v, f, src)
    t[src] = 0.0
    # faces around each vertex, to revisit only what a change can affect
    incidence = sp.csr_matrix((np.ones(3 * m, dtype=np.int8),
                               (f.ravel(), np.repeat(np.arange(m), 3))), shape=(n, m))
    is_src = np.zeros(n, dtype=bool)
    is_src[src] = True
    active = np.arange(m)
    passes = 0
    while active.size and passes < max_passes:
        passes += 1
        cand, ids = triangle_update(v, f[active], t)
        new = t.copy()
        np.minimum.at(new, ids, cand)
        new[is_src] = 0.0
        changed = np.flatnonzero(new < t - tolerance)
        t = new
        active = np.unique(incidence[changed].indices) if changed.size else changed
    return EikonalResult(t, passes, active.size == 0)
