"""The union of a surface's closed shells as one manifold surface (manifold3d).

A CAD export of an assembly is many closed shells that overlap or touch (cycloidal.ply: 100
bodies of a gear). ``load_surface`` counts their union's volume (``solid_volume``), but
fTetWild given the shells as they are must cut every triangle against every other where they
overlap, and meshes far more slowly than on the union's one boundary. ``union_shells``
returns that boundary: shells with positive volume joined, those with negative volume
(cavities) cut out of them. Used by ``--repair`` (``slicer.repair``) once the shells are
separate closed manifolds.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slicer.solid_volume import union_solid


def union_shells(vertices: NDArray[np.float64], faces: NDArray[np.integer]
                 ) -> tuple[NDArray[np.float64], NDArray[np.int64]] | None:
    """The boundary of ``solid_volume.union_solid``: (vertices (k, 3) float64, faces (f, 3)
    int64, outward wound, closed and manifold), in the input's units; None where manifold3d
    cannot read a shell."""
    union = union_solid(vertices, faces)
    if union is None:
        return None
    mesh = union.to_mesh64()
    return (np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3],
            np.asarray(mesh.tri_verts, dtype=np.int64))
