"""Boundary-conformal contours (paper eq. 9): iso-lines of the boundary distance."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slicer.errors import InputError
from slicer.toolpath.isolines import iso_lines
from slicer.toolpath.lines import SurfaceLines, empty_lines
from slicer.toolpath.surface import check_mesh


def contour_levels(max_distance: float, spacing: float, offset: float) -> NDArray[np.float64]:
    """(K,) float64 mm, the iso-values offset + k * spacing (k = 0, 1, ...) below max_distance."""
    if not spacing > 0:
        raise InputError(f"contour spacing must be positive, got {spacing} mm",
                         "check the toolpath width")
    if offset < 0:
        raise InputError(f"contour offset must be >= 0, got {offset} mm",
                         "use half a toolpath width")
    if max_distance <= offset:
        return np.zeros(0)
    k = np.arange(int(np.floor((max_distance - offset) / spacing)) + 1)
    levels = (offset + k * spacing).astype(np.float64)
    return np.asarray(levels[levels < max_distance], dtype=np.float64)


def contour_lines(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                  distance: NDArray[np.float64], spacing: float,
                  offset: float | None = None) -> SurfaceLines:
    """Contours d = offset + k * spacing, k = 0, 1, ... (eq. 9 with spacing = tau * W).

    distance: (n,) float64 mm from the boundary (``geodesic.boundary_distance``).
    spacing: mm between neighbouring contours; offset: mm of the first contour from the
    boundary, default half a spacing. Closed loops are flagged; a contour cut by a hole it
    does not surround (never for an exact distance) comes out open.
    """
    check_mesh(vertices, faces)
    d = np.asarray(distance, dtype=np.float64)
    if d.shape != (len(vertices),):
        raise InputError(f"distance must have one value per vertex ({len(vertices)}), "
                         f"got shape {d.shape}", "pass geodesic.boundary_distance(...)")
    off = 0.5 * spacing if offset is None else float(offset)
    levels = contour_levels(float(d[np.unique(faces)].max()), float(spacing), off)
    if len(levels) == 0:
        return empty_lines()
    return iso_lines(vertices, faces, d, levels)
