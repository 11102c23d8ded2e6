"""Discrete differential geometry on one layer: topology, Laplacian, gradients, fields.

Every function takes ``vertices: (n, 3) float64, mm`` and/or ``faces: (m, 3) int`` of a
triangle mesh (a curved layer component, open, possibly with holes) and is vectorised.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import splu

from core.errors import InputError
from core.tolerance import tol


class EdgeTopology(NamedTuple):
    """Unique edges of a triangle mesh.

    edges:      (E, 2) int64, vertex ids, edges[:, 0] < edges[:, 1].
    face_edge:  (m, 3) int64, face_edge[f, k] = edge between corners k and (k + 1) % 3.
    edge_faces: (E,) int64, number of faces using the edge (1 = boundary edge).
    """

    edges: NDArray[np.int64]
    face_edge: NDArray[np.int64]
    edge_faces: NDArray[np.int64]


def check_mesh(vertices: NDArray[np.float64], faces: NDArray[np.integer]) -> None:
    """Raise InputError unless vertices is (n, 3) finite and faces is (m, 3) indexing it."""
    v = np.asarray(vertices)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or not np.all(np.isfinite(v)):
        raise InputError(f"layer vertices must be a finite (n, 3) array, got shape {v.shape}",
                         "pass the layer mesh vertices in mm")
    if f.ndim != 2 or f.shape[1] != 3 or f.shape[0] == 0:
        raise InputError(f"layer faces must be a non-empty (m, 3) array, got shape {f.shape}",
                         "pass the triangles of the layer component")
    if f.min() < 0 or f.max() >= v.shape[0]:
        raise InputError("layer faces index vertices that do not exist",
                         "use faces numbered within the layer's own vertex array")


def _edge_keys(faces: NDArray[np.integer]) -> tuple[NDArray[np.int64], NDArray[np.int64], int]:
    """Half-edges (3m, 2) of face sides k = 0, 1, 2 and their undirected int64 keys."""
    f = np.asarray(faces, dtype=np.int64)
    half = np.stack([f, np.roll(f, -1, axis=1)], axis=2).reshape(-1, 2)  # (3m, 2), side k
    n = int(f.max()) + 1 if f.size else 1
    key = np.minimum(half[:, 0], half[:, 1]) * n + np.maximum(half[:, 0], half[:, 1])
    return half, key, n


def edge_topology(faces: NDArray[np.integer]) -> EdgeTopology:
    """Unique edges, the edge of each face side and how many faces use each edge."""
    _, key, n = _edge_keys(faces)
    ukey, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    edges = np.column_stack([ukey // n, ukey % n])
    return EdgeTopology(edges=edges, face_edge=inverse.reshape(-1, 3), edge_faces=counts)


def face_normals(vertices: NDArray[np.float64], faces: NDArray[np.integer]
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Unit face normals (m, 3) and face areas (m,) mm^2 (degenerate faces get normal 0)."""
    p = vertices[faces]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    norm = np.linalg.norm(cross, axis=1)
    normals = cross / np.maximum(norm, tol.zero)[:, None]
    return normals, 0.5 * norm


def vertex_normals(vertices: NDArray[np.float64], faces: NDArray[np.integer]
                   ) -> NDArray[np.float64]:
    """Area-weighted unit vertex normals (n, 3)."""
    p = vertices[faces]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])  # 2 * area * normal
    n = np.zeros_like(vertices, dtype=np.float64)
    for k in range(3):
        np.add.at(n, faces[:, k], cross)
    return n / np.maximum(np.linalg.norm(n, axis=1), tol.zero)[:, None]


def tangent_frames(normals: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Orthonormal tangent bases (e1, e2), each (k, 3), completing unit normals (k, 3)."""
    helper = np.where(np.abs(normals[:, [0]]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(normals, helper)
    e1 /= np.maximum(np.linalg.norm(e1, axis=1), tol.zero)[:, None]
    return e1, np.cross(normals, e1)


def boundary_edges(faces: NDArray[np.integer]) -> NDArray[np.int64]:
    """(B, 2) int64 boundary edges, oriented as in their face (interior on the left)."""
    half, key, _ = _edge_keys(faces)
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    return half[counts[inverse] == 1]


def boundary_vertices(faces: NDArray[np.integer], n_vertices: int) -> NDArray[np.bool_]:
    """(n,) bool, the vertex lies on a boundary edge."""
    mask = np.zeros(n_vertices, dtype=bool)
    mask[boundary_edges(faces).ravel()] = True
    return mask


def boundary_loops(faces: NDArray[np.integer]) -> list[NDArray[np.int64]]:
    """Boundary loops as ordered vertex-id arrays (first vertex not repeated).

    Uses the successor map of oriented boundary edges; a vertex where two loops touch is
    resolved by the edge order, which is enough for the manifold layers we get from slicing.
    """
    be = boundary_edges(faces)
    if len(be) == 0:
        return []
    n = int(be.max()) + 1
    graph = sp.coo_matrix((np.ones(len(be)), (be[:, 0], be[:, 1])), shape=(n, n)).tocsr()
    _, label = connected_components(graph, directed=True, connection="weak")
    used = np.zeros(n, dtype=bool)
    used[be.ravel()] = True
    succ = np.full(n, -1, dtype=np.int64)
    succ[be[:, 0]] = be[:, 1]
    loops: list[NDArray[np.int64]] = []
    for c in np.unique(label[used]):  # loop over loops, each walked in O(length)
        members = np.flatnonzero((label == c) & used)
        start = int(members.min())
        order = [start]
        v = int(succ[start])
        while v != start and v >= 0 and len(order) <= len(members):
            order.append(v)
            v = int(succ[v])
        loops.append(np.asarray(order, dtype=np.int64))
    return loops


def components(faces: NDArray[np.integer]) -> list[NDArray[np.int64]]:
    """Edge-connected components, each as an array of face indices (largest first)."""
    f = np.asarray(faces, dtype=np.int64)
    m = len(f)
    if m == 0:
        return []
    topo = edge_topology(f)
    fe = topo.face_edge.ravel()
    face_of = np.repeat(np.arange(m), 3)
    # bipartite face-edge incidence: faces sharing an edge end up in one component
    inc = sp.coo_matrix((np.ones(3 * m), (face_of, fe)), shape=(m, len(topo.edges))).tocsr()
    adj = inc @ inc.T
    _, label = connected_components(adj, directed=False)
    order = np.argsort(label, kind="stable")
    splits = np.flatnonzero(np.diff(label[order])) + 1
    groups = np.split(order, splits)
    groups.sort(key=len, reverse=True)
    return groups


def cotan_weights(vertices: NDArray[np.float64], faces: NDArray[np.integer]
                  ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """Per face side k (edge between corners k+1 and k+2): (i, j, w) arrays of length 3m.

    w = 0.5 * cot(angle at corner k); summing over the faces of an edge gives the cotangent
    weight 0.5 (cot a + cot b).
    """
    f = np.asarray(faces, dtype=np.int64)
    p = vertices[f]
    ii, jj, ww = [], [], []
    for k in range(3):
        a, b, c = p[:, k], p[:, (k + 1) % 3], p[:, (k + 2) % 3]
        u, v = b - a, c - a
        cross = np.linalg.norm(np.cross(u, v), axis=1)
        cot = np.einsum("ij,ij->i", u, v) / np.maximum(cross, tol.zero)
        ii.append(f[:, (k + 1) % 3])
        jj.append(f[:, (k + 2) % 3])
        ww.append(0.5 * cot)
    return np.concatenate(ii), np.concatenate(jj), np.concatenate(ww)


def cotan_laplacian(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                    robust: bool = False) -> sp.csr_matrix:
    """(n, n) positive semi-definite cotangent Laplacian L (x^T L x = sum w_ij (x_i - x_j)^2).

    ``robust`` uses the intrinsic Delaunay Laplacian with intrinsic mollification
    (robust-laplacian, Sharp & Crane 2020): its weights are non-negative on the sliver and
    zero-area triangles that marching tetrahedra produce, where libigl's intrinsic Delaunay
    flips never terminate (measured: unbounded memory on a collinear triangle).
    """
    n = len(vertices)
    if robust:
        import robust_laplacian

        lap, _mass = robust_laplacian.mesh_laplacian(
            np.ascontiguousarray(vertices, dtype=np.float64),
            np.ascontiguousarray(faces, dtype=np.int64),
            mollify_factor=1e-5,
        )
        return sp.csr_matrix(lap)
    i, j, w = cotan_weights(vertices, faces)
    off = sp.coo_matrix((-w, (i, j)), shape=(n, n))
    off = off + off.T
    diag = -np.asarray(off.sum(axis=1)).ravel()
    return sp.csr_matrix(off + sp.diags(diag))


def spd_solver(matrix: sp.spmatrix | sp.sparray) -> Callable[[NDArray[np.float64]],
                                                                 NDArray[np.float64]]:
    """Factor a sparse symmetric positive definite matrix once; return x = solve(b).

    Uses cholespy's sparse Cholesky (b may be (k,) or (k, r)); falls back to SuperLU when
    the Cholesky factorisation fails or gives a non-finite result (matrix not definite).
    """
    coo = sp.coo_matrix(matrix)
    k = coo.shape[0]
    try:
        from cholespy import CholeskySolverD, MatrixType

        chol = CholeskySolverD(k, coo.row.astype(np.int32), coo.col.astype(np.int32),
                               coo.data.astype(np.float64), MatrixType.COO)

        def solve(b: NDArray[np.float64]) -> NDArray[np.float64]:
            rhs = np.ascontiguousarray(b, dtype=np.float64)
            x = np.zeros_like(rhs)
            chol.solve(rhs, x)
            return x

        probe = solve(np.ones(k))
        if np.all(np.isfinite(probe)) and np.allclose(coo @ probe, 1.0, rtol=tol.computed,
                                                      atol=tol.computed):
            return solve
    except (RuntimeError, ValueError, ImportError):
        pass
    lu = splu(sp.csc_matrix(matrix))

    def solve_lu(b: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(lu.solve(np.ascontiguousarray(b, dtype=np.float64)))

    return solve_lu


def lumped_mass(vertices: NDArray[np.float64], faces: NDArray[np.integer]) -> NDArray[np.float64]:
    """(n,) float64 mm^2, a third of the area of the faces around each vertex."""
    _, area = face_normals(vertices, faces)
    mass = np.zeros(len(vertices))
    for k in range(3):
        np.add.at(mass, faces[:, k], area / 3.0)
    return mass


def face_gradient(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                  u: NDArray[np.float64]) -> NDArray[np.float64]:
    """(m, 3) gradient of the piecewise-linear per-vertex scalar u (n,) on each face."""
    p = vertices[faces]
    normal, area = face_normals(vertices, faces)
    grad = np.zeros((len(faces), 3))
    for k in range(3):
        opposite = p[:, (k + 2) % 3] - p[:, (k + 1) % 3]
        grad += u[faces[:, k]][:, None] * np.cross(normal, opposite)
    return grad / np.maximum(2.0 * area, tol.zero)[:, None]


def rotate_in_plane(vectors: NDArray[np.float64], normals: NDArray[np.float64]
                    ) -> NDArray[np.float64]:
    """(k, 3) tangent vectors rotated by +90 deg about the unit normals (k, 3)."""
    return np.cross(normals, vectors)


def _line_field_average(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                        field: NDArray[np.float64], weight: NDArray[np.float64]
                        ) -> NDArray[np.float64]:
    """Average a per-face line field (sign-free directions) over the faces' neighbourhood.

    Per vertex, face directions are written in the vertex tangent frame as complex numbers and
    squared (so d and -d agree), averaged with ``weight``; each face then averages its corners
    the same way. Returns (m, 3) unit directions in the face planes (0 where undefined).
    """
    n = len(vertices)
    vn = vertex_normals(vertices, faces)
    e1, e2 = tangent_frames(vn)
    acc = np.zeros(n, dtype=np.complex128)
    for k in range(3):
        vid = faces[:, k]
        c = np.einsum("ij,ij->i", field, e1[vid]) + 1j * np.einsum("ij,ij->i", field, e2[vid])
        np.add.at(acc, vid, weight * c**2 / np.maximum(np.abs(c) ** 2, tol.zero))
    fn, _ = face_normals(vertices, faces)
    f1, f2 = tangent_frames(fn)
    out = np.zeros(len(faces), dtype=np.complex128)
    for k in range(3):
        vid = faces[:, k]
        # the vertex's doubled direction, moved into the face plane via its 3D direction
        half = np.sqrt(acc[vid])
        d3 = half.real[:, None] * e1[vid] + half.imag[:, None] * e2[vid]
        c = np.einsum("ij,ij->i", d3, f1) + 1j * np.einsum("ij,ij->i", d3, f2)
        mag = np.abs(acc[vid])
        out += mag * c**2 / np.maximum(np.abs(c) ** 2, tol.zero)
    half = np.sqrt(out)
    res = half.real[:, None] * f1 + half.imag[:, None] * f2
    norm = np.linalg.norm(res, axis=1)
    return res / np.maximum(norm, tol.zero)[:, None]


def stripe_direction(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                     distance: NDArray[np.float64], smoothing: int = 3
                     ) -> NDArray[np.float64]:
    """(m, 3) unit per-face direction along which stripe lines run: across the contours.

    The paper's control field is z = (grad d / |grad d|)^perp (eq. 11), the direction of the
    phase gradient; stripe lines are the phase's level sets, so they run along z^perp, i.e.
    along grad d, perpendicular to the boundary-conformal contours. This returns that line
    direction (``stripe_lines`` rotates it back to z internally). Where |grad d| falls below 1
    (the ridge/medial axis of the distance, where the gradient flips or vanishes) the direction
    is blended with a line-field average of its neighbourhood, ``smoothing`` times.
    """
    g = face_gradient(vertices, faces, np.asarray(distance, dtype=np.float64))
    mag = np.linalg.norm(g, axis=1)
    d = g / np.maximum(mag, tol.zero)[:, None]
    _, area = face_normals(vertices, faces)
    # a geodesic distance has |grad d| = 1; less means the face straddles the ridge
    conf = np.clip(mag, 0.0, 1.0) ** 4
    for _ in range(smoothing):
        avg = _line_field_average(vertices, faces, d, area * conf)
        sign = np.sign(np.einsum("ij,ij->i", avg, d))
        sign[sign == 0] = 1.0
        blend = conf[:, None] * d + (1.0 - conf)[:, None] * sign[:, None] * avg
        d = blend / np.maximum(np.linalg.norm(blend, axis=1), tol.zero)[:, None]
        # smoothed faces count as half-trusted in the next pass, so the fix spreads inwards
        conf = np.maximum(conf, 0.5 * conf + 0.25)
    return d



PARALLEL_MIN_SINE = 0.5  # the fixed axis at least 30 deg off every face normal ...
PARALLEL_SHARE = 0.99  # ... over this share of the area, else no parallel field


def parallel_direction(vertices: NDArray[np.float64], faces: NDArray[np.integer]
                       ) -> NDArray[np.float64] | None:
    """(m, 3) unit per-face direction of parallel stripes: the surface's longest principal
    axis projected onto each face; None where that axis comes within 30 deg of the normal
    on more than 1 % of the area (a cap curving round: the projected field would be
    singular there, and ``stripe_direction`` is the safer field).

    Why: on a disc-like component (one boundary loop) the stripes across the contours run
    radially, and their count must fall towards the centre: they lie wider than W at the
    rim and converge inside (11-13 % of a disc layer left bare, 7 % covered twice, measured
    by ``coverage``). A field without singularities gives evenly spaced stripes, joined by
    U-turns along the boundary (a zig-zag raster following the curved layer).
    """
    if len(faces) == 0:
        return None
    centre = vertices.mean(axis=0)
    _, _, vt = np.linalg.svd(vertices - centre, full_matrices=False)
    normal, area = face_normals(vertices, faces)
    along = vt[0] - (normal @ vt[0])[:, None] * normal
    sine = np.linalg.norm(along, axis=1)
    if float(area[sine >= PARALLEL_MIN_SINE].sum()) < PARALLEL_SHARE * float(area.sum()):
        return None
    return along / np.maximum(sine, tol.zero)[:, None]
