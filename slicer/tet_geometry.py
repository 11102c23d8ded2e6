"""Array primitives of a tet mesh: signed volumes, positive orientation, unused vertices dropped.

Shared by the mesh reader (``slicer.mesh_io``), fTetWild's post-processing
(``slicer.tetrahedralize``) and red refinement (``slicer.refine``); kept apart so none of
them imports another for three small functions.
"""

from __future__ import annotations

import numpy as np


def tet_volumes(vertices: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volume of each tet, mm^3: (T,) float64, positive when det(p1-p0, p2-p0, p3-p0) > 0.

    Args:
        vertices: (V, 3) float64, mm.
        tets: (T, 4) int, vertex indices.
    """
    p = vertices[tets]
    a, b, c = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    return np.einsum("ij,ij->i", np.cross(a, b), c) / 6.0


def orient_positive(vertices: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """The tets with the last two vertices swapped where the volume is negative: (T, 4) int32."""
    out = np.array(tets, dtype=np.int32, copy=True)
    negative = tet_volumes(vertices, out) < 0
    out[negative, 2], out[negative, 3] = out[negative, 3], out[negative, 2].copy()
    return out


def compact(vertices: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop vertices no cell uses and renumber: ((V', 3) float64, (C, k) int32)."""
    used, inverse = np.unique(cells, return_inverse=True)
    return (
        np.asarray(vertices, dtype=np.float64)[used],
        inverse.reshape(cells.shape).astype(np.int32),
    )
