"""Discrete P1 operators on a tetrahedral mesh: gradient, divergence, Laplacian, face adjacency.

Everything is built with vectorised numpy / scipy.sparse, with no Python loop over tets.

Conventions:
    * A scalar field ``g`` lives on vertices, piecewise linear (P1) inside each tet, so its
      gradient is one constant vector per tet.
    * The gradient operator ``grad`` is a sparse ``(3T, V)`` matrix with **tet-major rows**:
      row ``3 * t + c`` is component ``c`` (0 = x, 1 = y, 2 = z) of the gradient in tet ``t``.
      Hence ``(grad @ g).reshape(T, 3)`` is the per-tet gradient.
    * The divergence of a per-tet vector field ``v`` (T, 3) is the weak (integrated) divergence
      ``D v = grad^T diag(vol) v``: a (V,) vector in mm^3 * (unit of v) / mm. It is the adjoint
      of the gradient in the volume-weighted inner product, ``<grad g, v>_vol = g . D v``.
    * The Laplacian is the cotangent (stiffness) matrix ``L = grad^T M grad`` with
      ``M = diag(repeat(vol, 3))``: symmetric positive semi-definite, constants in its kernel.
      Sign: ``g . L g = sum_t vol_t |grad g|^2 >= 0``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from core.errors import InputError
from core.stages import TetMesh
from core.tolerance import tol

# The four faces of a tet (v0, v1, v2, v3), face k is opposite local vertex k. For a positively
# oriented tet these vertex orders give outward normals (right-hand rule).
TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], dtype=np.int64)
# The six edges of a tet as local vertex pairs.
TET_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]], dtype=np.int64)


def signed_volumes(vertices: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volume of each tet.

    Args:
        vertices: (V, 3) float64, mm.
        tets: (T, 4) int, vertex indices.

    Returns:
        (T,) float64, mm^3; positive when (v1 - v0, v2 - v0, v3 - v0) is right-handed.
    """
    p = vertices[tets]
    e1, e2, e3 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    return np.einsum("ij,ij->i", e1, np.cross(e2, e3)) / 6.0


def orient_tets(vertices: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, int]:
    """Swap two vertices of every negatively oriented tet.

    Args:
        vertices: (V, 3) float64, mm.
        tets: (T, 4) int, vertex indices.

    Returns:
        (tets (T, 4) int64 all with signed volume >= 0, number of tets that were flipped).
    """
    out = np.array(tets, dtype=np.int64, copy=True)
    neg = signed_volumes(vertices, out) < 0
    out[neg, 2], out[neg, 3] = out[neg, 3], out[neg, 2].copy()
    return out, int(neg.sum())


@dataclass(frozen=True, eq=False)
class BoundaryFaces:
    """Faces that belong to exactly one tet.

    Attributes:
        faces: (B, 3) int64, vertex indices, ordered so the normal (right-hand rule) points out.
        normal: (B, 3) float64, unit outward normal.
        area: (B,) float64, mm^2.
        tet: (B,) int64, the tet owning each face.
    """

    faces: np.ndarray
    normal: np.ndarray
    area: np.ndarray
    tet: np.ndarray

    def __len__(self) -> int:
        return len(self.faces)


@dataclass(frozen=True, eq=False)
class TetOperators:
    """The discrete operators of one tet mesh (see the module docstring for conventions).

    Attributes:
        vertices: (V, 3) float64, mm.
        tets: (T, 4) int64, positively oriented vertex indices.
        volume: (T,) float64, mm^3, tet volumes (0 for degenerate tets).
        grad: (3T, V) CSR float64, 1/mm, tet-major rows (row 3t + c = component c in tet t).
        face_pairs: (F, 2) int64, pairs of tets sharing an interior face (first < second).
        face_area: (F,) float64, mm^2, area of that shared face.
        boundary: the boundary faces.
        flipped: int, number of input tets that were negatively oriented and fixed.
        degenerate: int, number of tets with (near) zero volume (their gradient rows are 0).
    """

    vertices: np.ndarray
    tets: np.ndarray
    volume: np.ndarray
    grad: sp.csr_matrix
    face_pairs: np.ndarray
    face_area: np.ndarray
    boundary: BoundaryFaces
    flipped: int = 0
    degenerate: int = 0
    _cache: dict[str, object] = field(default_factory=dict, repr=False)

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def n_tets(self) -> int:
        return len(self.tets)

    def gradient(self, g: np.ndarray) -> np.ndarray:
        """Per-tet gradient of a vertex field.

        Args:
            g: (V,) float64 (or (V, k) for k fields).

        Returns:
            (T, 3) float64 in (unit of g)/mm; (T, 3, k) for a (V, k) input.
        """
        out = self.grad @ g
        return out.reshape(self.n_tets, 3, *np.shape(g)[1:])

    def divergence(self, v: np.ndarray) -> np.ndarray:
        """Weak divergence ``grad^T diag(vol) v`` of a per-tet vector field.

        Args:
            v: (T, 3) float64.

        Returns:
            (V,) float64, mm^2 * (unit of v): the adjoint of ``gradient`` under vol-weighting.
        """
        weighted = (np.asarray(v, dtype=np.float64) * self.volume[:, None]).reshape(-1)
        return np.asarray(self.grad.T @ weighted)

    @property
    def divergence_matrix(self) -> sp.csr_matrix:
        """(V, 3T) CSR: ``grad^T diag(repeat(vol, 3))``, tet-major columns."""
        if "div" not in self._cache:
            mass = sp.diags(np.repeat(self.volume, 3))
            self._cache["div"] = sp.csr_matrix(self.grad.T @ mass)
        return self._cache["div"]

    @property
    def divergence_components(self) -> tuple[sp.csr_matrix, sp.csr_matrix, sp.csr_matrix]:
        """(D_x, D_y, D_z), each (V, T) CSR: ``D v = D_x v_x + D_y v_y + D_z v_z``."""
        div = sp.csc_matrix(self.divergence_matrix)
        return tuple(sp.csr_matrix(div[:, c::3]) for c in range(3))

    @property
    def laplacian(self) -> sp.csr_matrix:
        """(V, V) CSR, cotangent stiffness ``grad^T M grad``: symmetric PSD, L @ 1 = 0."""
        if "lap" not in self._cache:
            lap = sp.csr_matrix(self.divergence_matrix @ self.grad)
            lap = sp.csr_matrix((lap + lap.T) * 0.5)  # exact symmetry despite rounding
            lap.sum_duplicates()
            self._cache["lap"] = lap
        return self._cache["lap"]

    def face_laplacian(self, weight: np.ndarray | None = None) -> sp.csr_matrix:
        """(T, T) CSR graph Laplacian of the tet face-adjacency graph.

        Args:
            weight: (F,) float64, weight per interior face; default the face area (mm^2).

        Returns:
            (T, T) CSR, symmetric PSD, ``v . Lf v = sum_f w_f |v_i - v_j|^2``.
        """
        w = self.face_area if weight is None else np.asarray(weight, dtype=np.float64)
        i, j = self.face_pairs[:, 0], self.face_pairs[:, 1]
        n = self.n_tets
        adj = sp.coo_matrix((np.concatenate([w, w]), (np.concatenate([i, j]),
                            np.concatenate([j, i]))), shape=(n, n)).tocsr()
        deg = np.asarray(adj.sum(axis=1)).ravel()
        return sp.csr_matrix(sp.diags(deg) - adj)

    @cached_property
    def tet_centroid(self) -> np.ndarray:
        """(T, 3) float64, mm."""
        return self.vertices[self.tets].mean(axis=1)


def _pack_faces(tri: np.ndarray, n_vertices: int) -> np.ndarray:
    """A unique int64 key per unordered triangle (vertex triple)."""
    s = np.sort(tri, axis=1).astype(np.int64)
    n = np.int64(n_vertices)
    if n_vertices ** 3 < 2**62:
        return (s[:, 0] * n + s[:, 1]) * n + s[:, 2]
    # Very large meshes: fall back to a row-unique id (slower, still vectorised).
    _, key = np.unique(s, axis=0, return_inverse=True)
    return key.astype(np.int64).ravel()


def build_operators(mesh: TetMesh) -> TetOperators:
    """All discrete operators of a tet mesh, tets oriented positively first.

    Args:
        mesh: the tet mesh (vertices mm, tets (T, 4)).

    Returns:
        The operators. Raises InputError for an empty mesh.
    """
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    if len(mesh.tets) == 0:
        raise InputError("the tet mesh has no tetrahedra", "check the model and the edge length")
    tets, flipped = orient_tets(vertices, mesh.tets)
    n_tets, n_vertices = len(tets), len(vertices)

    p = vertices[tets]
    e1, e2, e3 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    c23, c31, c12 = np.cross(e2, e3), np.cross(e3, e1), np.cross(e1, e2)
    det = np.einsum("ij,ij->i", e1, c23)
    scale = np.maximum(np.einsum("ij,ij->i", e1, e1), tol.zero) ** 1.5
    good = det > tol.zero * scale
    inv = np.where(good, 1.0 / np.where(good, det, 1.0), 0.0)
    # Gradients of the barycentric coordinates lambda_1..3 are the rows of J^-1 (J = [e1 e2 e3]),
    # i.e. cofactor / det; lambda_0 = 1 - sum, so its gradient is minus their sum.
    gl = np.empty((n_tets, 4, 3))
    gl[:, 1] = c23 * inv[:, None]
    gl[:, 2] = c31 * inv[:, None]
    gl[:, 3] = c12 * inv[:, None]
    gl[:, 0] = -(gl[:, 1] + gl[:, 2] + gl[:, 3])
    volume = np.where(good, det / 6.0, 0.0)

    rows = (3 * np.arange(n_tets)[:, None, None] + np.arange(3)[None, None, :])  # (T,1,3)
    rows = np.broadcast_to(rows, (n_tets, 4, 3))
    cols = np.broadcast_to(tets[:, :, None], (n_tets, 4, 3))
    grad = sp.csr_matrix(
        (gl.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * n_tets, n_vertices)
    )

    # Faces: 4 per tet, face k opposite local vertex k. Interior faces appear twice.
    tri = tets[:, TET_FACES].reshape(-1, 3)  # (4T, 3), outward order
    owner = np.repeat(np.arange(n_tets, dtype=np.int64), 4)
    key = _pack_faces(tri, n_vertices)
    order = np.argsort(key, kind="stable")
    sk = key[order]
    same_next = sk[1:] == sk[:-1]
    first = np.flatnonzero(same_next)  # positions i with sk[i] == sk[i+1]
    pair_a, pair_b = owner[order[first]], owner[order[first + 1]]
    face_pairs = np.stack([np.minimum(pair_a, pair_b), np.maximum(pair_a, pair_b)], axis=1)
    pts = vertices[tri[order[first]]]
    face_area = 0.5 * np.linalg.norm(np.cross(pts[:, 1] - pts[:, 0], pts[:, 2] - pts[:, 0]),
                                     axis=1)

    single = np.ones(len(sk), dtype=bool)
    single[first] = False
    single[first + 1] = False
    bidx = order[single]
    bfaces = tri[bidx]
    bp = vertices[bfaces]
    cross = np.cross(bp[:, 1] - bp[:, 0], bp[:, 2] - bp[:, 0])
    norm = np.linalg.norm(cross, axis=1)
    barea = 0.5 * norm
    bnormal = cross / np.maximum(norm, tol.zero)[:, None]
    btet = owner[bidx]
    # Degenerate tets can give inconsistent orientation; make normals point away from the
    # opposite vertex anyway.
    opposite = vertices[tets[btet, bidx % 4]]
    wrong = np.einsum("ij,ij->i", bnormal, opposite - bp[:, 0]) > 0
    bfaces[wrong] = bfaces[wrong][:, [0, 2, 1]]
    bnormal[wrong] *= -1.0
    boundary = BoundaryFaces(faces=bfaces, normal=bnormal, area=barea, tet=btet)

    return TetOperators(
        vertices=vertices,
        tets=tets,
        volume=volume,
        grad=grad,
        face_pairs=face_pairs,
        face_area=face_area,
        boundary=boundary,
        flipped=flipped,
        degenerate=int((~good).sum()),
    )
