"""Map lines found on the deformed layer back to the original layer (paper eqs. 15, 16).

The deformed layer has the original connectivity, so a point with barycentric coordinates
``bary`` in face ``f`` of the deformed layer maps to the same barycentric combination of the
original face's vertices. Its printing direction is the original layer's unit normal there,
oriented along the growth direction: the barycentric blend of area-weighted vertex normals
(``point_normals``), which is the face normal of the smooth layer; the raw normal of the
face itself is arbitrary on the slivers that marching tetrahedra leave (on the socket, 55
waypoints deviated 20-73 degrees from both path neighbours, all on faces of area ~1/200 of
the median).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from core.tolerance import tol
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


def vertex_normals(
    vertices: NDArray[np.float64], faces: NDArray[np.int32], direction: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Area-weighted unit vertex normals, oriented along the growth direction.

    Each face adds its growth-oriented cross product (twice its area times its unit normal)
    to its three corners, so a sliver (a near-degenerate triangle of marching tetrahedra,
    whose own normal is arbitrary) adds almost nothing.

    Args:
        vertices: (n, 3) float64, mm.
        faces: (m, 3) int32.
        direction: (n, 3) float64, unit growth direction per vertex.

    Returns:
        (n, 3) float64, unit; a vertex whose faces cancel takes its growth direction.
    """
    tri = vertices[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flip = np.einsum("ij,ij->i", cross, direction[faces].sum(axis=1)) < 0
    cross[flip] *= -1.0
    acc = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(acc, faces[:, k], cross)
    norm = np.linalg.norm(acc, axis=1)
    good = norm > tol.zero
    out = np.array(direction, dtype=np.float64, copy=True)
    out[good] = acc[good] / norm[good, None]
    dnorm = np.linalg.norm(out, axis=1)
    out /= np.where(dnorm > tol.zero, dnorm, 1.0)[:, None]
    return out


def point_normals(
    vnormals: NDArray[np.float64], faces: NDArray[np.int32], fnormals: NDArray[np.float64],
    face: NDArray[np.int32], bary: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Unit normals at surface points: the barycentric blend of the vertex normals.

    This is the face normal of eq. 16 for the smooth layer the mesh samples: on a flat or
    evenly meshed layer it equals the face normal, while marching-tet slivers (area ~1e-3 of
    their neighbours, measured on the socket) no longer give isolated 40-70 degree spikes.

    Args:
        vnormals: (n, 3) float64, unit, from ``vertex_normals``.
        faces: (m, 3) int32.
        fnormals: (m, 3) float64, unit face normals (used where the blend cancels).
        face: (P,) int32; bary: (P, 3) float64.

    Returns:
        (P, 3) float64, unit.
    """
    blend = interpolate(vnormals, faces, face, bary)
    norm = np.linalg.norm(blend, axis=1)
    good = norm > tol.unit
    out = fnormals[face].copy()
    out[good] = blend[good] / norm[good, None]
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
