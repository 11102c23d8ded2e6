"""The real-valued alternative to stripes of the paper's comparison: iso-lines of a potential.

``poisson_potential`` is the phi whose gradient best matches the direction turned by 90 deg in
each face (a Poisson problem, Neumann boundary); its iso-lines phi = k * spacing run along the
direction. Unlike the stripe field it cannot place branch points, so where the line count must
change the lines crowd or spread; kept to compare against (``pattern = "poisson"``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from core.tolerance import tol
from slicer.toolpath.isolines import iso_lines
from slicer.toolpath.lines import SurfaceLines, empty_lines
from slicer.toolpath.stripes import check_stripe_inputs, per_component
from slicer.toolpath.surface import (
    cotan_laplacian,
    face_gradient,
    face_normals,
    rotate_in_plane,
    spd_solver,
)


def poisson_potential(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                      direction: NDArray[np.float64]) -> NDArray[np.float64]:
    """(n,) phi minimising sum_f area |grad phi - z_f|^2 (L phi = div z), z = direction^perp.

    Neumann boundary; the constant is fixed by a zero mean. phi is then scaled so that its
    area-weighted mean gradient norm is 1 (so phi is a length in mm where |grad phi| = 1).
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    n = len(v)
    fn, area = face_normals(v, f)
    zf = rotate_in_plane(np.asarray(direction, dtype=np.float64), fn)
    p = v[f]
    rhs = np.zeros(n)
    for k in range(3):
        opp = p[:, (k + 2) % 3] - p[:, (k + 1) % 3]
        grad_b = np.cross(fn, opp) / np.maximum(2.0 * area, tol.zero)[:, None]
        np.add.at(rhs, f[:, k], area * np.einsum("ij,ij->i", zf, grad_b))
    lap = cotan_laplacian(v, f)
    used = np.unique(f)
    pin = int(used[0])
    free = np.setdiff1d(used, [pin])
    # the Neumann problem is solvable (rhs sums to zero); pinning one vertex fixes the constant
    solve = spd_solver(lap[free][:, free])
    phi = np.zeros(n)
    phi[free] = solve(rhs[free])
    g = np.linalg.norm(face_gradient(v, f, phi), axis=1)
    mean_g = float((g * area).sum() / max(area.sum(), tol.zero))
    phi = phi - phi[used].mean()
    return phi / max(mean_g, tol.zero)


def poisson_stripe_lines(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                         direction: NDArray[np.float64], spacing: float) -> SurfaceLines:
    """The real-valued alternative of the paper's comparison: lines phi = k * spacing."""
    check_stripe_inputs(vertices, faces, direction, spacing)
    return per_component(_poisson_lines_one, vertices, faces, direction, spacing)


def _poisson_lines_one(vertices: NDArray[np.float64], faces: NDArray[np.int64],
                       direction: NDArray[np.float64], spacing: float) -> SurfaceLines:
    phi = poisson_potential(vertices, faces, direction)
    used = np.unique(faces)
    lo, hi = float(phi[used].min()), float(phi[used].max())
    k = np.arange(np.floor(lo / spacing), np.ceil(hi / spacing) + 1)
    levels = k * spacing
    levels = levels[(levels > lo) & (levels < hi)]
    if len(levels) == 0:
        return empty_lines()
    return iso_lines(vertices, faces, phi, levels)
