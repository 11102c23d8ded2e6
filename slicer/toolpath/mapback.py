"""Map lines found on the deformed layer back to the original layer (paper eqs. 15, 16).

The deformed layer has the original connectivity, so a point with barycentric coordinates
``bary`` in face ``f`` of the deformed layer maps to the same barycentric combination of the
original face's vertices. Its printing direction is the original face's unit normal, oriented
along the growth direction.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slicer.tolerance import tol
from slicer.toolpath.lines import SurfaceLines


def face_normals(
    vertices: NDArray[np.float64], faces: NDArray[np.int32], direction: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Unit normals of the faces, each flipped to agree with the growth direction.

    Args:
        vertices: (n, 3) float64, mm.
        faces: (m, 3) int32.
        direction: (n, 3) float64, unit growth direction per vertex.

    Returns:
        (m, 3) float64, unit; a degenerate face takes its vertices' mean direction.
    """
    tri = vertices[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(cross, axis=1)
    grow = direction[faces].sum(axis=1)
    good = norm > tol.zero
    out = np.empty_like(cross)
    out[good] = cross[good] / norm[good, None]
    gnorm = np.linalg.norm(grow, axis=1)
    fallback = ~good & (gnorm > tol.zero)
    out[fallback] = grow[fallback] / gnorm[fallback, None]
    out[~good & ~fallback] = (0.0, 0.0, 1.0)
    # The Layers contract orients faces along growth; enforce it per face anyway.
    flip = np.einsum("ij,ij->i", out, grow) < 0
    out[flip] *= -1.0
    return out


def interpolate(
    values: NDArray[np.float64],
    faces: NDArray[np.int32],
    face: NDArray[np.int32],
    bary: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Barycentric interpolation of per-vertex ``values`` ((n,) or (n, k)) at points.

    Args:
        values: (n,) or (n, k) float64, per-vertex values.
        faces: (m, 3) int32.
        face: (P,) int32, face of each point.
        bary: (P, 3) float64, barycentric coordinates.

    Returns:
        (P,) or (P, k) float64.
    """
    corner = values[faces[face]]  # (P, 3) or (P, 3, k)
    if corner.ndim == 2:
        return np.einsum("pj,pj->p", corner, bary)
    return np.einsum("pjk,pj->pk", corner, bary)


def map_back(lines: SurfaceLines, vertices: NDArray[np.float64], faces: NDArray[np.int32]) -> (
    SurfaceLines
):
    """Lines found on a mesh with the connectivity ``faces``, placed on ``vertices`` (eq. 16).

    Args:
        lines: polylines on the deformed layer (face, bary refer to ``faces``).
        vertices: (n, 3) float64, mm, original layer vertices.
        faces: (m, 3) int32, the shared connectivity.

    Returns:
        The same lines (face, bary, line, closed unchanged) with points on the original layer.
    """
    bary = np.clip(lines.bary, 0.0, None)
    bary = bary / np.maximum(bary.sum(axis=1, keepdims=True), tol.zero)
    points = interpolate(vertices, faces, lines.face, bary)
    return SurfaceLines(points, lines.face.astype(np.int32), bary, lines.line, lines.closed)


def barycentric(
    points: NDArray[np.float64], vertices: NDArray[np.float64], faces: NDArray[np.int32],
    face: NDArray[np.int32],
) -> NDArray[np.float64]:
    """Barycentric coordinates of ``points`` projected onto the planes of ``face`` (eq. 15).

    Args:
        points: (P, 3) float64, mm.
        vertices: (n, 3) float64, mm.
        faces: (m, 3) int32.
        face: (P,) int32.

    Returns:
        (P, 3) float64, sum 1 (may be negative outside the triangle).
    """
    tri = vertices[faces[face]]
    e1 = tri[:, 1] - tri[:, 0]
    e2 = tri[:, 2] - tri[:, 0]
    d = points - tri[:, 0]
    a11 = np.einsum("ij,ij->i", e1, e1)
    a12 = np.einsum("ij,ij->i", e1, e2)
    a22 = np.einsum("ij,ij->i", e2, e2)
    b1 = np.einsum("ij,ij->i", d, e1)
    b2 = np.einsum("ij,ij->i", d, e2)
    det = a11 * a22 - a12 * a12
    det = np.where(np.abs(det) > tol.zero, det, tol.zero)
    u = (a22 * b1 - a12 * b2) / det
    w = (a11 * b2 - a12 * b1) / det
    return np.stack([1.0 - u - w, u, w], axis=1)
