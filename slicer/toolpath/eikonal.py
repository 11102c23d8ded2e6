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
not to the nearest boundary vertex. The updates run to their fixed point in a compiled
label-correcting loop (``_solve``): a queue of vertices seeded with the sources; taking one
updates the corners opposite each edge it ends, and a corner whose distance falls by more than
the tolerance joins the queue. The update is monotone, so the order of the updates does not
change the fixed point, only how many it takes; Jacobi passes over all triangles from
Dijkstra's graph distance (the vectorised solver before session 14; ``triangle_update`` gives
one pass's candidates) reach the same distances to 1e-6 mm, in 10-20 x the time.

Where two fronts meet (the medial axis, a disc's centre) the distance has a kink that the
linear interpolation along an edge cuts, so there it falls short by up to about half an edge.
On a disc that is the difference between an innermost contour and a hole at the centre (the
hemisphere's layers: a 5.8 mm hole in a 40 mm disc). A planar component needs no
propagation at all: its distance from the boundary is the Euclidean distance to the nearest
boundary segment (in a plane the nearest boundary point is always in sight), exact at the
medial axis too (``planar_boundary_distance``). On a curved component the distance is never
below the straight-line distance to the boundary segments, which is nearly the geodesic one
on a gently curved layer; ``surface_distance`` takes the larger of the two, which repairs the
kinks wherever the layer does not fold back.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from core.tolerance import tol

ZERO = tol.zero  # numba kernels read module constants, not attributes

class EikonalResult(NamedTuple):
    """Distance from a source set and how the solve went.

    distance: (n,) float64, mm, per vertex (0 on the sources, inf where unreachable).
    passes:   int, vertex visits of the solve over n, rounded up (the sweeps they amount to).
    converged: bool, False when ``max_passes`` x n visits stopped it first (the distance is
        then still an upper bound, at least as good as the graph distance).
    """

    distance: NDArray[np.float64]
    passes: int
    converged: bool


def triangle_update(v: NDArray[np.float64], f: NDArray[np.int64], t: NDArray[np.float64]
                    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Candidate distances of each triangle's corners from their opposite edges.

    For corners c of rotations (a, b, c) of ``f`` (m, 3): min over l in [0, 1] of
    t_a + l (t_b - t_a) + |a + l (b - a) - c|, a convex function of l whose stationary
    point is l* = (-p - dt sqrt(|e x d0|^2 / (|e|^2 - dt^2))) / |e|^2 with d0 = a - c,
    e = b - a, p = d0 . e, dt = t_b - t_a (when |dt| >= |e| the minimum is at an end).

    A corner whose edge has an unknown (inf) end is reached along the edge from the known one.
    Returns ((3m,) float64 mm candidates, (3m,) int64 the corner each is for), rotation k of
    face i at k m + i.
    """
    out: tuple[NDArray[np.float64], NDArray[np.int64]] = _triangle_candidates(
        np.ascontiguousarray(v, dtype=np.float64), np.ascontiguousarray(f, dtype=np.int64),
        np.asarray(t, dtype=np.float64))
    return out


@njit(cache=True)
def _triangle_candidates(v: NDArray[np.float64], f: NDArray[np.int64], t: NDArray[np.float64]
                         ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    m = len(f)
    cand = np.empty(3 * m)
    ids = np.empty(3 * m, dtype=np.int64)
    for k in range(3):
        for i in range(m):
            a, b, c = f[i, k], f[i, (k + 1) % 3], f[i, (k + 2) % 3]
            cand[k * m + i] = _via_edge(v, a, b, c, t[a], t[b])
            ids[k * m + i] = c
    return cand, ids


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
    is_src = np.zeros(n, dtype=bool)
    is_src[src] = True
    t, visits, stopped = _solve(v, f, is_src, float(tolerance), int(max_passes) * n)
    return EikonalResult(t, -(-int(visits) // n), not stopped)


@njit(cache=True)
def _via_edge(v: NDArray[np.float64], a: int, b: int, c: int, ta: float, tb: float) -> float:
    """The distance of corner c through the edge a-b whose ends are at ``ta``, ``tb``
    (``triangle_update``): ee = |b - a|^2, p = (a - c) . (b - a), q = |a - c|^2, bc = |b - c|."""
    ex, ey, ez = v[b, 0] - v[a, 0], v[b, 1] - v[a, 1], v[b, 2] - v[a, 2]
    dx, dy, dz = v[a, 0] - v[c, 0], v[a, 1] - v[c, 1], v[a, 2] - v[c, 2]
    fx, fy, fz = v[b, 0] - v[c, 0], v[b, 1] - v[c, 1], v[b, 2] - v[c, 2]
    return _candidate(ta, tb, ex * ex + ey * ey + ez * ez, dx * ex + dy * ey + dz * ez,
                      dx * dx + dy * dy + dz * dz, np.sqrt(fx * fx + fy * fy + fz * fz))


@njit(cache=True)
def _candidate(ta: float, tb: float, ee: float, p: float, q: float, bc: float) -> float:
    """The minimum over l in [0, 1] of ta + l (tb - ta) + |a + l (b - a) - c| (module doc)."""
    if not (np.isfinite(ta) and np.isfinite(tb)):
        return min(ta + np.sqrt(q), tb + bc)
    dt = tb - ta
    cross = max(ee * q - p * p, 0.0)
    room = ee - dt * dt
    if room > ZERO * max(ee, ZERO):
        lam = (-p - dt * np.sqrt(cross / room)) / max(ee, ZERO)
    else:
        lam = 0.0 if dt > 0.0 else 1.0
    lam = min(max(lam, 0.0), 1.0)
    return ta + lam * dt + np.sqrt(max(q + 2.0 * lam * p + lam * lam * ee, 0.0))


@njit(cache=True)
def _solve(v: NDArray[np.float64], f: NDArray[np.int64], is_src: NDArray[np.bool_],
           tolerance: float, max_visits: int) -> tuple[NDArray[np.float64], int, bool]:
    """The distance (n,) from the vertices ``is_src`` at the fixed point of the triangle
    updates (module doc), by a label-correcting queue seeded with the sources.

    A vertex x taken from the queue updates, in each face around it, the two other corners
    through their edges to x; a corner whose distance falls by more than ``tolerance`` joins
    the queue (at most once at a time: a ring buffer of n). Every fixed point lies below the
    graph distance (a corner is never farther than through an edge end), so starting from
    inf rather than from Dijkstra's distance reaches the same one.
    Returns (distance, vertex visits, whether max_visits stopped it first).
    """
    n, m = len(v), len(f)
    # faces around each vertex (CSR by a counting sort)
    ptr = np.zeros(n + 1, dtype=np.int64)
    for i in range(m):
        for k in range(3):
            ptr[f[i, k] + 1] += 1
    for x in range(n):
        ptr[x + 1] += ptr[x]
    fill = ptr[:-1].copy()
    around = np.empty(3 * m, dtype=np.int64)
    for i in range(m):
        for k in range(3):
            x = f[i, k]
            around[fill[x]] = i
            fill[x] += 1
    t = np.full(n, np.inf)
    queue = np.empty(n, dtype=np.int64)
    queued = np.zeros(n, dtype=np.bool_)
    head, size = 0, 0
    for x in range(n):
        if is_src[x]:
            t[x] = 0.0
            queue[size] = x
            queued[x] = True
            size += 1
    visits = 0
    while size > 0:
        if visits >= max_visits:
            return t, visits, True
        x = queue[head]
        head = (head + 1) % n
        size -= 1
        queued[x] = False
        visits += 1
        for j in range(ptr[x], ptr[x + 1]):
            i = around[j]
            for k in range(3):
                if f[i, k] == x:
                    y, z = f[i, (k + 1) % 3], f[i, (k + 2) % 3]
            for turn in range(2):
                c, o = (y, z) if turn == 0 else (z, y)
                if is_src[c]:
                    continue
                cand = _via_edge(v, x, o, c, t[x], t[o])  # c through the edge x-o
                if cand < t[c]:
                    fell = t[c] - cand
                    t[c] = cand
                    if fell > tolerance and not queued[c]:
                        queue[(head + size) % n] = c
                        queued[c] = True
                        size += 1
    return t, visits, False


PLANAR_TOLERANCE = 1e-6  # flat: every vertex within this x the component's size of a plane
SUBSEGMENTS = 0.5  # boundary pieces searched are at most this x the median boundary edge
NEAREST_PIECES = 16  # boundary pieces checked exactly per vertex


def is_planar(vertices: NDArray[np.float64], faces: NDArray[np.integer],
              tolerance: float = PLANAR_TOLERANCE) -> bool:
    """True if the vertices used by ``faces`` lie on one plane (relative ``tolerance``)."""
    p = np.asarray(vertices, dtype=np.float64)[np.unique(np.asarray(faces))]
    if len(p) < 4:
        return True
    q = p - p.mean(axis=0)
    size = float(np.linalg.norm(q, axis=1).max())
    if size <= 0.0:
        return True
    normal = np.linalg.svd(q, full_matrices=False)[2][-1]
    return bool(np.abs(q @ normal).max() <= tolerance * size + tol.zero)


def segment_distance(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                     edges: NDArray[np.integer]) -> NDArray[np.float64]:
    """(n,) float64, mm, Euclidean distance of each vertex to the nearest of ``edges``.

    edges: (B, 2) vertex ids of segments (e.g. boundary edges); see ``points_to_segments``.
    Vertices not used by a face get 0; without edges every vertex gets inf.
    """
    v = np.asarray(vertices, dtype=np.float64)
    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    out = np.zeros(len(v))
    used = np.unique(np.asarray(faces, dtype=np.int64))
    out[used] = points_to_segments(v[used], v[e[:, 0]], v[e[:, 1]])
    return out


def points_to_segments(points: NDArray[np.float64], a: NDArray[np.float64],
                       b: NDArray[np.float64]) -> NDArray[np.float64]:
    """(P,) float64, mm, Euclidean distance of each point to the nearest segment a-b.

    points: (P, 3) mm; a, b: (B, 3) mm segment ends. The segments are cut into pieces of at
    most SUBSEGMENTS x their median length; each point checks the NEAREST_PIECES pieces with
    the nearest midpoints exactly. Without segments every point gets inf.
    """
    x = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(a) == 0:
        return np.full(len(x), np.inf)
    pa, pb = split_segments(a, b)
    kk = min(NEAREST_PIECES, len(pa))
    _, near = cKDTree(0.5 * (pa + pb)).query(x, k=kk)
    out: NDArray[np.float64] = _nearest_piece_distance(
        x, pa, pb, np.asarray(near, dtype=np.int64).reshape(len(x), kk))
    return out


@njit(cache=True)
def _nearest_piece_distance(x: NDArray[np.float64], pa: NDArray[np.float64],
                            pb: NDArray[np.float64], near: NDArray[np.int64]
                            ) -> NDArray[np.float64]:
    """(P,) mm, the distance of each point x (P, 3) to the nearest of its pieces ``near``
    (P, k) (ends pa, pb (S, 3) mm): ``nearest_feet``'s minimum without its (P, k, 3)
    temporaries."""
    out = np.empty(len(x))
    for i in range(len(x)):
        best = np.inf
        for j in range(near.shape[1]):
            s = near[i, j]
            ab0, ab1, ab2 = pb[s, 0] - pa[s, 0], pb[s, 1] - pa[s, 1], pb[s, 2] - pa[s, 2]
            ax0, ax1, ax2 = x[i, 0] - pa[s, 0], x[i, 1] - pa[s, 1], x[i, 2] - pa[s, 2]
            u = (ax0 * ab0 + ax1 * ab1 + ax2 * ab2) / max(ab0 * ab0 + ab1 * ab1 + ab2 * ab2,
                                                          ZERO)
            u = min(max(u, 0.0), 1.0)
            d0, d1, d2 = ax0 - u * ab0, ax1 - u * ab1, ax2 - u * ab2
            best = min(best, d0 * d0 + d1 * d1 + d2 * d2)
        out[i] = np.sqrt(best)
    return out


def split_segments(a: NDArray[np.float64], b: NDArray[np.float64]
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Segments a-b ((B, 3) mm) cut into pieces of at most SUBSEGMENTS x their median
    length: (S, 3), (S, 3) mm piece ends, so that the nearest midpoints find the nearest
    pieces."""
    length = np.linalg.norm(b - a, axis=1)
    piece = SUBSEGMENTS * max(float(np.median(length)), tol.zero)
    cuts = np.maximum(np.ceil(length / piece).astype(np.int64), 1)
    owner = np.repeat(np.arange(len(a)), cuts)
    k = np.arange(len(owner)) - np.repeat(np.cumsum(cuts) - cuts, cuts)
    t0, t1 = k / cuts[owner], (k + 1) / cuts[owner]
    d = (b - a)[owner]
    return a[owner] + t0[:, None] * d, a[owner] + t1[:, None] * d


def segment_feet(p: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64]
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Distance (...) mm and foot (..., 3) mm of points p on segments a-b (all (..., 3) mm,
    broadcast against each other)."""
    ab = b - a
    t = np.einsum("...j,...j->...", p - a, ab) / np.maximum(
        np.einsum("...j,...j->...", ab, ab), tol.zero)
    foot = a + np.clip(t, 0.0, 1.0)[..., None] * ab
    return np.asarray(np.linalg.norm(p - foot, axis=-1)), foot


def nearest_feet(points: NDArray[np.float64], pa: NDArray[np.float64],
                 pb: NDArray[np.float64], k: int
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """Distances (P, k) mm, feet (P, k, 3) mm and piece indices (P, k) from each point to
    the k pieces pa-pb with the nearest midpoints (fewer columns when there are fewer
    pieces)."""
    tree = cKDTree(0.5 * (pa + pb))
    kk = min(k, len(pa))
    _, near = tree.query(points, k=kk)
    near = np.asarray(near, dtype=np.int64).reshape(len(points), kk)
    dist, foot = segment_feet(points[:, None, :], pa[near], pb[near])
    return dist, foot, near


def planar_boundary_distance(vertices: NDArray[np.float64], faces: NDArray[np.integer]
                             ) -> NDArray[np.float64]:
    """(n,) float64, mm, Euclidean distance of each vertex to the nearest boundary segment:
    the exact distance from the boundary of a flat component (``segment_distance``)."""
    from slicer.toolpath.surface import boundary_edges

    return segment_distance(vertices, faces, boundary_edges(faces))


def surface_distance(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                     sources: NDArray[np.integer]) -> NDArray[np.float64]:
    """(n,) float64, mm, distance over the surface from the boundary vertices ``sources``
    (a whole boundary, or some of its loops), as accurate as the component allows.

    Flat, with the whole boundary as source: the exact Euclidean distance. Otherwise the
    eikonal distance, raised to the Euclidean distance from the source segments (the
    boundary edges with both ends in ``sources``) where it falls below it: a straight line
    is never longer than a path on the surface, so that only undoes the cut at the kinks
    (a curved disc's centre), and where the surface folds back (a shortcut through the air)
    the eikonal distance is the larger and stays.
    """
    from slicer.toolpath.surface import boundary_edges

    f = np.asarray(faces, dtype=np.int64)
    src = np.unique(np.asarray(sources, dtype=np.int64).ravel())
    edges = boundary_edges(f)
    is_src = np.zeros(len(vertices), dtype=bool)
    is_src[src] = True
    own = edges[is_src[edges[:, 0]] & is_src[edges[:, 1]]]
    whole = len(own) == len(edges)
    if whole and is_planar(vertices, f):
        return planar_boundary_distance(vertices, f)
    d = eikonal_distance(vertices, f, src).distance
    if len(own) == 0:  # sources that are not boundary loops: nothing straight to compare
        return d
    return np.maximum(d, np.where(np.isfinite(d), segment_distance(vertices, f, own), 0.0))
