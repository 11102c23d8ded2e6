"""The medial line of a narrow strip: one line along its middle, and the strip's width.

A strip about one filament wide (a thin wall cut by a layer, a rib, a sliver between two
holes) holds one line. Without holes (a single boundary loop) or with many (walls between
holes) there are no two sides to take the middle between (``SurfaceGeometry.centre_lines``
needs an outer loop and inner ones); the medial axis is found instead where the nearest
boundary point jumps from one side of the strip to the other: along every mesh edge whose
two ends see their nearest boundary in nearly opposite directions (more than MEDIAL_ANGLE
apart; a corner where the sides meet at a right angle is no strip, a sharp tip is), at the
point equally far from both feet's boundary pieces. The crossings are chained face by face
into polylines (``isolines.lines_from_segments``). Euclidean distances: a strip this narrow
is nearly flat across.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from core.tolerance import tol
from slicer.toolpath.eikonal import nearest_feet, segment_feet, split_segments
from slicer.toolpath.isolines import Nodes, lines_from_segments
from slicer.toolpath.line_ends import extend_to_boundary
from slicer.toolpath.lines import SurfaceLines, empty_lines
from slicer.toolpath.surface import boundary_edges, edge_topology, face_normals, vertex_normals

MEDIAL_ANGLE = 120.0  # deg: directions to the nearest boundary at least this far apart
NEAREST = 16  # boundary pieces searched per vertex for the nearest
OTHER_SIDE = 64  # ... for the boundary on either side of a line
TANGENT_SPAN = 3  # a line's direction: over this many points either way (crossings wiggle)


def _outward(vertices: NDArray[np.float64], faces: NDArray[np.int32],
             edges: NDArray[np.int64]) -> NDArray[np.float64]:
    """(n, 3) unit outward boundary normals in the tangent plane at the boundary vertices
    (zero elsewhere): the mean of their boundary edges' (interior on the left)."""
    normal = vertex_normals(vertices, faces)
    t = vertices[edges[:, 1]] - vertices[edges[:, 0]]
    out = np.zeros_like(vertices)
    for k in range(2):
        np.add.at(out, edges[:, k], np.cross(t, normal[edges[:, k]]))
    return out / np.maximum(np.linalg.norm(out, axis=1), tol.zero)[:, None]


def medial_lines(vertices: NDArray[np.float64], faces: NDArray[np.int32]) -> SurfaceLines:
    """The medial line(s) of a narrow strip (module docstring); empty without a boundary.

    vertices: (n, 3) float64 mm; faces: (m, 3) int32, one component (any number of loops).
    The medial axis stops where the strip's sides stop facing each other (its tips, the
    corners where a wall turns), about half a strip width from the boundary there; open
    ends are carried on to the boundary (``line_ends.extend_to_boundary``).
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    bnd = boundary_edges(f)
    if len(bnd) == 0 or len(f) == 0:
        return empty_lines()
    pa, pb = split_segments(v[bnd[:, 0]], v[bnd[:, 1]])
    d, u, piece = _towards_boundary(v, f, bnd, pa, pb)

    topo = edge_topology(f)
    i, j = topo.edges[:, 0], topo.edges[:, 1]
    crossed = ((np.einsum("ij,ij->i", u[i], u[j]) < np.cos(np.radians(MEDIAL_ANGLE)))
               & (topo.edge_faces == 2))
    # equal distance to the two feet's pieces along the edge (linear between the ends)
    phi_i = d[i] - segment_feet(v[i], pa[piece[j]], pb[piece[j]])[0]
    phi_j = segment_feet(v[j], pa[piece[i]], pb[piece[i]])[0] - d[j]
    t = np.clip(-phi_i / np.where(np.abs(phi_j - phi_i) > tol.zero, phi_j - phi_i, 1.0),
                0.0, 1.0)
    t = np.where(np.abs(phi_j - phi_i) > tol.zero, t, 0.5)

    fc = crossed[topo.face_edge]  # (m, 3): side k (corners k, k + 1) crossed
    # a face with two crossed sides holds a segment; one with three (where the medial
    # axis branches) keeps the segment between its first two
    face_id = np.flatnonzero(fc.sum(axis=1) >= 2)
    sides = np.argsort(~fc[face_id], axis=1, kind="stable")[:, :2]  # (S, 2) crossed sides
    keys, pts, face, bary = [], [], [], []
    for s in range(2):
        k = sides[:, s]
        e = topo.face_edge[face_id, k]
        a_corner, b_corner = f[face_id, k], f[face_id, (k + 1) % 3]
        # t runs from the edge's lower vertex id to its higher one
        te = np.where(a_corner == topo.edges[e, 0], t[e], 1.0 - t[e])
        bc = np.zeros((len(face_id), 3))
        bc[np.arange(len(face_id)), k] = 1.0 - te
        bc[np.arange(len(face_id)), (k + 1) % 3] = te
        pts.append((1.0 - te)[:, None] * v[a_corner] + te[:, None] * v[b_corner])
        keys.append(e)
        face.append(face_id)
        bary.append(bc)
    if len(face_id) == 0:
        return empty_lines()
    nodes = Nodes(key=np.concatenate(keys), point=np.concatenate(pts),
                  face=np.concatenate(face).astype(np.int32), bary=np.concatenate(bary))
    lines = lines_from_segments(nodes, np.stack(keys, axis=1))
    return extend_to_boundary(lines, v, f.astype(np.int32))


def strip_width(vertices: NDArray[np.float64], faces: NDArray[np.int32],
                lines: SurfaceLines) -> NDArray[np.float64]:
    """(n,) float64 mm, the strip's width across its medial ``lines`` at the line point
    nearest to each vertex (``across_width``; NaN without lines): the width a medial line
    prints at, interpolated from the vertices like every process value."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    bnd = boundary_edges(f)
    if len(bnd) == 0 or len(lines.points) < 2:
        return np.full(len(v), np.nan)
    normal = face_normals(v, f)[0][lines.face]
    width = across_width(lines.points, lines.line, normal, v[bnd[:, 0]], v[bnd[:, 1]])[0]
    ok = np.isfinite(width)
    if not ok.any():
        return np.full(len(v), np.nan)
    _, near = cKDTree(lines.points[ok]).query(v)
    return np.asarray(width[ok][near], dtype=np.float64)


def across_width(points: NDArray[np.float64], line: NDArray[np.int32],
                 normal: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64],
                 rows: NDArray[np.int64] | None = None
                 ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """(P,) float64 mm, the width of the strip across each line point: from the boundary
    on one side to the boundary on the other, along the surface's direction perpendicular
    to the line there (in the tangent plane; NaN where a side is not among the OTHER_SIDE
    nearest boundary pieces). Unlike the nearest boundary on either side, this is the
    strip's width at a line's end too, where the nearest boundary is the end itself.

    points: (P, 3) mm, polylines stored consecutively; line: (P,) their ids; normal: (P, 3)
    unit surface normals; a, b: (B, 3) mm, the boundary segments' ends; rows: only these
    points (the results then have len(rows) entries). Also returns (P,) bool: the nearest
    boundary lies ahead of the point along its line rather than across it (near an end).
    """
    all_p = np.asarray(points, dtype=np.float64)
    i = np.arange(len(all_p)) if rows is None else np.asarray(rows, dtype=np.int64)
    out = np.full(len(i), np.nan)
    if len(all_p) < 2 or len(a) == 0 or len(i) == 0:
        return out, np.zeros(len(i), dtype=bool)
    start = np.flatnonzero(np.concatenate([[True], line[1:] != line[:-1]]))
    stop = np.concatenate([start[1:], [len(all_p)]])
    first = np.repeat(start, stop - start)[i]
    last = np.repeat(stop - 1, stop - start)[i]
    tangent = (all_p[np.minimum(i + TANGENT_SPAN, last)]
               - all_p[np.maximum(i - TANGENT_SPAN, first)])
    p = all_p[i]
    across = np.cross(np.asarray(normal)[i], tangent)
    across /= np.maximum(np.linalg.norm(across, axis=1), tol.zero)[:, None]
    along = np.cross(across, np.asarray(normal)[i])
    pa, pb = split_segments(a, b)
    k = min(OTHER_SIDE, len(pa))
    _, near = cKDTree(0.5 * (pa + pb)).query(p, k=k)
    near = np.asarray(near, dtype=np.int64).reshape(len(p), k)
    ra, rb = pa[near] - p[:, None, :], pb[near] - p[:, None, :]  # (P, k, 3)
    ta, tb = np.einsum("pkj,pj->pk", ra, along), np.einsum("pkj,pj->pk", rb, along)
    sa, sb = np.einsum("pkj,pj->pk", ra, across), np.einsum("pkj,pj->pk", rb, across)
    hit = (ta <= 0.0) != (tb <= 0.0)  # the piece crosses the line across the strip
    s = sa + (sb - sa) * ta / np.where(hit, ta - tb, 1.0)
    left = np.where(hit & (s > 0.0), s, np.inf).min(axis=1)
    right = np.where(hit & (s <= 0.0), -s, np.inf).min(axis=1)
    ok = np.isfinite(left) & np.isfinite(right)
    out[ok] = left[ok] + right[ok]
    ab = rb - ra
    t = np.clip(-np.einsum("pkj,pkj->pk", ra, ab)
                / np.maximum(np.einsum("pkj,pkj->pk", ab, ab), tol.zero), 0.0, 1.0)
    foot = ra + t[..., None] * ab  # (P, k, 3) relative to the point
    nearest = foot[np.arange(len(p)), np.argmin(np.linalg.norm(foot, axis=2), axis=1)]
    ahead = (np.abs(np.einsum("pj,pj->p", nearest, along))
             > np.abs(np.einsum("pj,pj->p", nearest, across)))
    return out, ahead


def _towards_boundary(v: NDArray[np.float64], f: NDArray[np.int64], bnd: NDArray[np.int64],
                      pa: NDArray[np.float64], pb: NDArray[np.float64]
                      ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """Distance (n,) mm to the nearest boundary piece, unit direction (n, 3) towards it
    (the outward normal at a boundary vertex) and the piece's index (n,)."""
    d, foot, piece = _nearest_piece(v, pa, pb)
    u = (foot - v) / np.maximum(d, tol.zero)[:, None]
    on_boundary = d <= tol.slack * max(float(np.ptp(v, axis=0).max()), tol.zero)
    u = np.where(on_boundary[:, None], _outward(v, f.astype(np.int32), bnd), u)
    return d, u, piece


def _nearest_piece(x: NDArray[np.float64], pa: NDArray[np.float64], pb: NDArray[np.float64]
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """Distance (n,) mm, foot (n, 3) mm and index (n,) of the nearest piece pa-pb to each
    point x (n, 3), among the NEAREST with the nearest midpoints."""
    dist, feet, near = nearest_feet(x, pa, pb, NEAREST)
    best = np.argmin(dist, axis=1)
    rows = np.arange(len(x))
    return dist[rows, best], feet[rows, best], near[rows, best]
