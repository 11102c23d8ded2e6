"""Stripes printed as wide as their local spacing.

Stripes across the contours of a disc-like layer run radially: their count must change with
the radius, and one stripe added between two neighbours halves their spacing. Between two
branch points the spacing therefore grows by up to 2x (s to 2 s), so lines of one width W
leave wedges bare where they diverge and cover strips twice where they converge, whatever
the branch points' placement: with the spacing spread evenly over [2/3, 4/3] W (the best
split) about 8 % of the area stays bare and 8 % is covered twice. A line whose width follows
the distance to its two neighbours (``stripe_width_scale``) fills the wedge instead; the
nozzle speed sets that width (W = C / (H v)), as it does for contours fitted to a band.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from slicer.toolpath.eikonal import segment_feet
from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.mapback import interpolate
from slicer.toolpath.surface import face_normals
from slicer.toolpath.surface_geometry import CENTRE_WIDTH_SCALE

SIDE_REACH = 2.0  # x spacing: a neighbouring stripe farther than this on a side is none
PARALLEL_COS = np.cos(np.radians(45.0))  # a stripe met at a steeper angle is no neighbour
SMOOTH_POINTS = 2  # the width is averaged over this many line points on either side


def side_gaps(lines: SurfaceLines, normals: NDArray[np.float64], reach: float
              ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Distance from each line point to the nearest other line on its left and on its right.

    lines: the stripes; normals: (P, 3) unit surface normal at each line point. Sides are
    taken across the line's own direction in the tangent plane; only segments of other
    lines within ``reach`` (mm) running within 45 deg of the point's line count.
    Returns two (P,) float64 mm arrays, inf where a side has no such neighbour.
    """
    p = lines.points
    ln = lines.line.astype(np.int64)
    n_pts = len(p)
    left = np.full(n_pts, np.inf)
    right = np.full(n_pts, np.inf)
    seg = np.flatnonzero(ln[1:] == ln[:-1])
    if len(seg) == 0:
        return left, right
    head = np.flatnonzero(np.concatenate([[True], ln[1:] != ln[:-1]]))
    size = np.diff(np.concatenate([head, [n_pts]]))
    first = np.repeat(head, size)
    last = first + np.repeat(size, size) - 1
    idx = np.arange(n_pts)
    tangent = p[np.minimum(idx + 1, last)] - p[np.maximum(idx - 1, first)]
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1), 1e-300)[:, None]
    side = np.cross(normals, tangent)
    a, b = p[seg], p[seg + 1]
    half = 0.5 * float(np.linalg.norm(b - a, axis=1).max())
    pairs = cKDTree(p).sparse_distance_matrix(cKDTree(0.5 * (a + b)), reach + half,
                                              output_type="ndarray")
    pi = pairs["i"].astype(np.int64)
    si = pairs["j"].astype(np.int64)
    other = ln[pi] != ln[seg[si]]
    pi, si = pi[other], si[other]
    direction = b[si] - a[si]
    cos = np.abs(np.einsum("ij,ij->i", direction, tangent[pi])) / np.maximum(
        np.linalg.norm(direction, axis=1), 1e-300)
    pi, si = pi[cos >= PARALLEL_COS], si[cos >= PARALLEL_COS]
    _, foot = segment_feet(p[pi], a[si], b[si])
    d = foot - p[pi]
    d -= np.einsum("ij,ij->i", d, normals[pi])[:, None] * normals[pi]
    dist = np.linalg.norm(d, axis=1)
    across = np.einsum("ij,ij->i", d, side[pi])
    near = dist <= reach
    np.minimum.at(left, pi[near & (across > 0)], dist[near & (across > 0)])
    np.minimum.at(right, pi[near & (across <= 0)], dist[near & (across <= 0)])
    return left, right


def stripe_width_scale(vertices: NDArray[np.float64], faces: NDArray[np.int32],
                       lines: SurfaceLines, distance: NDArray[np.float64], spacing: float
                       ) -> NDArray[np.float64]:
    """(n,) float64, per vertex: the width the nearest stripe should print at over
    ``spacing``, within CENTRE_WIDTH_SCALE.

    At a line point the band reaches halfway to the neighbouring stripe on each side (the
    mean of the two gaps); a side without a neighbour within SIDE_REACH x spacing reaches
    the boundary if it is nearer (twice the boundary distance ``distance``, (n,) mm), else
    mirrors the other side. Each vertex takes the value of its nearest line point, so the
    scale interpolated along a line is its own. vertices (n, 3) mm, faces (m, 3).
    """
    n = len(vertices)
    if len(lines.points) < 2:
        return np.ones(n)
    fn, _ = face_normals(vertices, faces)
    normals = fn[lines.face]
    reach = SIDE_REACH * spacing
    left, right = side_gaps(lines, normals, reach)
    to_boundary = 2.0 * interpolate(distance, faces, lines.face, lines.bary)
    left = np.where(np.isinf(left) & (to_boundary < reach), to_boundary, left)
    right = np.where(np.isinf(right) & (to_boundary < reach), to_boundary, right)
    left = np.where(np.isinf(left), right, left)
    right = np.where(np.isinf(right), left, right)
    gap = np.where(np.isinf(left), spacing, 0.5 * (left + right))
    gap = _smooth_along(gap, lines.line)
    scale = np.clip(gap / spacing, *CENTRE_WIDTH_SCALE)
    _, nearest = cKDTree(lines.points).query(vertices)
    return np.asarray(scale[nearest], dtype=np.float64)


def _smooth_along(values: NDArray[np.float64], line: NDArray[np.int32]) -> NDArray[np.float64]:
    """(P,) ``values`` averaged over SMOOTH_POINTS points either side along each line."""
    ln = line.astype(np.int64)
    total = values.copy()
    count = np.ones(len(values))
    for k in range(1, SMOOTH_POINTS + 1):  # a few shifts, each vectorised
        for shift in (k, -k):
            src = np.roll(np.arange(len(values)), shift)
            same = ln[src] == ln
            if shift > 0:
                same[:shift] = False
            else:
                same[shift:] = False
            total += np.where(same, values[src], 0.0)
            count += same
    return total / count
