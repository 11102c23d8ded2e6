"""Vertices where a layer component's boundary distance peaks between its vertices.

A layer is the marching-tets cut of the tet mesh, so its triangles are about a tet edge
long (2-3 mm on the bundled examples), and a disc's centre often lies inside a triangle whose
corners are 2-3 mm from it. The boundary distance lives on the vertices and is linear in each
triangle, so its peak is cut off there: on the hemisphere's layers the largest distance fell
short of the disc's radius by up to 2.9 mm (median 1.6 mm, about 0.7 W). Eq. 9's innermost
loop then closed 2-4 mm out, and the stripes' converging ends stopped as far, leaving a pocket
of gel at each disc's centre: 93 % of the hemisphere's simulated pore volume and its largest
surface error, -1.6 to -3.3 mm (session 12).

``add_distance_peaks`` inserts a vertex where the distance peaks inside a triangle: for each
interior local maximum of the vertex distances (a vertex at least as far from the boundary as
its neighbours), the Euclidean distance to the boundary edges is sampled on a barycentric grid
over the faces within two rings of it; where the best sample beats the vertex by more than
PEAK_GAIN x W, its face is split in three there (a conforming split: no T-junctions, nothing
else of the mesh changes). Samples keep a barycentric coordinate of at least MIN_BARY, so no
sliver triangle is made.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

PEAK_GAIN = 0.1  # insert where the peak beats the best vertex by more than this x W
MAX_PEAKS = 16  # local maxima examined per component, farthest first
GRID = 8  # barycentric grid resolution of the samples per face
MIN_BARY = 0.15  # no sample closer than this (barycentric) to a face's edge


def _grid(n: int, lo: float) -> NDArray[np.float64]:
    """(S, 3) barycentric points on an n-step grid, each coordinate at least ``lo``."""
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = i + j <= n
    b = np.column_stack([i[keep], j[keep], n - i[keep] - j[keep]]) / n
    return b[np.all(b >= lo, axis=1)]


def add_distance_peaks(vertices: NDArray[np.float64], faces: NDArray[np.int32],
                       width: NDArray[np.float64]
                       ) -> tuple[NDArray[np.float64], NDArray[np.int32],
                                  NDArray[np.int32], NDArray[np.float64]]:
    """Split the faces where the boundary distance peaks between vertices (module doc).

    Args:
        vertices: (n, 3) float64, mm; faces: (m, 3) int32, a component with a boundary.
        width: (n,) float64, mm, the toolpath width W per vertex (sets PEAK_GAIN's scale).

    Returns:
        vertices: (n + k, 3), the new vertices appended; faces: (m + 2k, 3), each split face
        replaced by its first part, the two others appended; parent: (k,) int32, the face
        (of the input) each new vertex lies in; bary: (k, 3) float64, its barycentric
        coordinates there (to interpolate per-vertex values onto the new vertices).
    """
    from slicer.toolpath.eikonal import points_to_segments
    from slicer.toolpath.surface import boundary_edges

    none = (vertices, faces, np.zeros(0, dtype=np.int32), np.zeros((0, 3)))
    if len(faces) == 0:
        return none
    edges = boundary_edges(faces)
    if len(edges) == 0:
        return none
    a, b = vertices[edges[:, 0]], vertices[edges[:, 1]]
    dist = points_to_segments(vertices, a, b)
    on_boundary = np.zeros(len(vertices), dtype=bool)
    on_boundary[edges.ravel()] = True
    pairs = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    neighbour_max = np.full(len(vertices), -np.inf)
    np.maximum.at(neighbour_max, pairs[:, 0], dist[pairs[:, 1]])
    np.maximum.at(neighbour_max, pairs[:, 1], dist[pairs[:, 0]])
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    peaks = np.flatnonzero(used & ~on_boundary & (dist >= neighbour_max))
    peaks = peaks[np.argsort(-dist[peaks])][:MAX_PEAKS]
    grid = _grid(GRID, MIN_BARY)
    split: dict[int, NDArray[np.float64]] = {}
    for v in peaks:  # a few local maxima per component
        ring1 = np.flatnonzero(np.any(faces == v, axis=1))
        near = np.unique(faces[ring1])
        ring2 = np.flatnonzero(np.any(np.isin(faces, near), axis=1))
        samples = np.einsum("sk,fkj->fsj", grid, vertices[faces[ring2]]).reshape(-1, 3)
        d = points_to_segments(samples, a, b)
        best = int(np.argmax(d))
        if d[best] - dist[v] <= PEAK_GAIN * float(width[v]):
            continue
        face = int(ring2[best // len(grid)])
        if face not in split:
            split[face] = grid[best % len(grid)]
    if not split:
        return none
    parent = np.array(sorted(split), dtype=np.int32)
    bary = np.array([split[int(f)] for f in parent])
    corners = faces[parent]
    new = len(vertices) + np.arange(len(parent))
    out_v = np.concatenate([vertices, np.einsum("pk,pkj->pj", bary, vertices[corners])])
    out_f = faces.copy()
    # (a, b, c) -> (a, b, p), (b, c, p), (c, a, p): the orientation is kept
    out_f[parent] = np.column_stack([corners[:, 0], corners[:, 1], new])
    extra = np.concatenate([np.column_stack([corners[:, 1], corners[:, 2], new]),
                            np.column_stack([corners[:, 2], corners[:, 0], new])])
    return out_v, np.concatenate([out_f, extra]).astype(np.int32), parent, bary
