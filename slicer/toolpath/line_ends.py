"""Open line ends carried on to the boundary: a strip's medial line reaching its ends.

The medial line of a strip stops where the strip's sides stop facing each other, about half
a strip width short of a square end (the corners' bisectors meet there). A band printed
along it then leaves that much bare at each end, and its volume falls short by the same
share (on a short strip, a third of it). Each open end is carried straight on, along the
line's direction at the end, until it reaches the boundary (at most REACH x its distance
to the nearest boundary: the end of a strip lies farther than its sides where the strip
is longer than wide), so the band's square end reaches the boundary. An end that has
another line within JUNCTION x that distance (where medial lines meet, a wall joining
another) stays, and a walk stops as near to another line: carrying it on would print over
the other. The new points are projected onto the surface (the nearest of the CANDIDATES
faces with the nearest centres), STEP x the mean edge length apart, so consecutive points
share a face or neighbouring faces as resampling needs; the walk stops where the surface
ends.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from core.tolerance import tol
from slicer.toolpath.eikonal import points_to_segments
from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.mapback import barycentric, interpolate
from slicer.toolpath.resample import line_index
from slicer.toolpath.surface import boundary_edges

JUNCTION = 1.5  # another line nearer than this x the end's boundary distance: a junction
REACH = 2.0  # the walk goes on for at most this x that distance, until the surface ends
STEP = 0.4  # extension points this x the mean edge length apart
CANDIDATES = 8  # faces searched for the projection of each extension point
TANGENT_POINTS = 3  # the end's direction: from this many points back along the line
OFF_SURFACE = 0.05  # a projection this x STEP beside its target (in the surface): the edge


def extend_to_boundary(lines: SurfaceLines, vertices: NDArray[np.float64],
                       faces: NDArray[np.int32]) -> SurfaceLines:
    """``lines`` with every open end carried on to the boundary (module docstring).

    vertices: (n, 3) float64 mm; faces: (m, 3) int32, the surface the lines lie on; the
    extension at an end is its Euclidean distance to the nearest boundary edge.
    """
    if lines.n_lines == 0 or len(faces) == 0:
        return lines
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    edge = float(np.mean(np.linalg.norm(v[f] - v[np.roll(f, 1, axis=1)], axis=2)))
    step = STEP * max(edge, tol.zero)
    centres = cKDTree(v[f].mean(axis=1))
    tree = cKDTree(lines.points)
    idx = line_index(lines)
    bnd = boundary_edges(f)
    d_at = points_to_segments(lines.points, v[bnd[:, 0]], v[bnd[:, 1]])
    parts: list[tuple[NDArray[np.float64], NDArray[np.int32], NDArray[np.float64]]] = []
    for k in range(lines.n_lines):
        lo, hi = int(idx.start[k]), int(idx.stop[k])
        pts, face, bary = lines.points[lo:hi], lines.face[lo:hi], lines.bary[lo:hi]
        if not lines.closed[k] and hi - lo >= 2:
            back = min(TANGENT_POINTS, hi - lo - 1)
            head = _walk(pts[0], pts[0] - pts[back], float(d_at[lo]), k, lines.line, tree,
                         v, f, centres, step)
            tail = _walk(pts[-1], pts[-1] - pts[-1 - back], float(d_at[hi - 1]), k,
                         lines.line, tree, v, f, centres, step)
            pts = np.concatenate([head[0][::-1], pts, tail[0]])
            face = np.concatenate([head[1][::-1], face, tail[1]])
            bary = np.concatenate([head[2][::-1], bary, tail[2]])
        parts.append((pts, face, bary))
    counts = np.array([len(p[0]) for p in parts])
    return SurfaceLines(
        points=np.concatenate([p[0] for p in parts]),
        face=np.concatenate([p[1] for p in parts]).astype(np.int32),
        bary=np.concatenate([p[2] for p in parts]),
        line=np.repeat(np.arange(lines.n_lines), counts).astype(np.int32),
        closed=lines.closed.copy(),
    )


def _walk(end: NDArray[np.float64], direction: NDArray[np.float64], length: float, own: int,
          line: NDArray[np.int32], tree: cKDTree, v: NDArray[np.float64],
          f: NDArray[np.int64], centres: cKDTree, step: float
          ) -> tuple[NDArray[np.float64], NDArray[np.int32], NDArray[np.float64]]:
    """Points (k, 3), faces (k,) and barycentrics (k, 3) from ``end`` on along
    ``direction`` until the surface ends, at most REACH x ``length`` mm (the end's
    distance to the boundary); none at a junction."""
    none = (np.zeros((0, 3)), np.zeros(0, np.int32), np.zeros((0, 3)))
    norm = float(np.linalg.norm(direction))
    if length <= 0.25 * step or norm <= tol.zero:
        return none
    others = [i for i in tree.query_ball_point(end, JUNCTION * length) if line[i] != own]
    if others:
        return none
    near_side, length = length, REACH * length  # the end may lie farther than a side
    n = int(np.ceil(length / step))
    target = end + (np.arange(1, n + 1) * (length / n))[:, None] * (direction / norm)
    kk = min(CANDIDATES, len(f))
    _, near = centres.query(target, k=kk)
    near = np.asarray(near, dtype=np.int64).reshape(n, kk)
    best = np.full(n, np.inf)
    face = np.zeros(n, dtype=np.int32)
    bary = np.zeros((n, 3))
    for c in range(kk):
        fc = near[:, c].astype(np.int32)
        b = np.clip(barycentric(target, v, f.astype(np.int32), fc), 0.0, None)
        b /= np.maximum(b.sum(axis=1, keepdims=True), tol.zero)
        off = interpolate(v, f.astype(np.int32), fc, b) - target
        tri = v[f[fc]]
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normal /= np.maximum(np.linalg.norm(normal, axis=1), tol.zero)[:, None]
        # off the surface within its plane (past its edge), not across it (a curved strip)
        dist = np.linalg.norm(off - np.einsum("ij,ij->i", off, normal)[:, None] * normal,
                              axis=1)
        better = dist < best
        best = np.where(better, dist, best)
        face = np.where(better, fc, face)
        bary = np.where(better[:, None], b, bary)
    on = best <= OFF_SURFACE * step
    # no nearer to another line than at the end: a wall running into a junction stops
    kk = min(8, len(line))
    dist, idx = tree.query(target, k=kk)
    dist = np.where(line[np.asarray(idx).reshape(n, kk)] != own, np.asarray(dist).reshape(n, kk),
                    np.inf).min(axis=1)
    on &= dist > JUNCTION * near_side
    stop = int(np.argmin(on)) if not on.all() else n
    pts = interpolate(v, f.astype(np.int32), face[:stop], bary[:stop])
    return pts, face[:stop], bary[:stop]
