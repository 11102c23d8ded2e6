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

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from slicer.solid_volume import shells, signed_volume

if TYPE_CHECKING:
    import manifold3d as m3d


def union_solid(vertices: NDArray[np.float64], faces: NDArray[np.integer]
                ) -> m3d.Manifold | None:
    """manifold3d's union of the shells of ``vertices`` (n, 3) float64 and ``faces`` (m, 3)
    int (closed, outward wound), cavities cut out; None where a shell is not a closed
    manifold manifold3d can read."""
    import manifold3d as m3d

    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    label = shells(f)
    solid: list[m3d.Manifold] = []
    cavity: list[m3d.Manifold] = []
    order = np.argsort(label, kind="stable")
    bounds = np.searchsorted(label[order], np.arange(int(label.max(initial=-1)) + 2))
    for k in range(len(bounds) - 1):
        part = f[order[bounds[k]:bounds[k + 1]]]
        used, local = np.unique(part, return_inverse=True)
        tri = local.reshape(-1, 3)
        volume = signed_volume(v[used], tri)
        if volume < 0:
            tri = tri[:, ::-1]  # a cavity, read outward to be cut out
        shell = m3d.Manifold(m3d.Mesh64(vert_properties=np.asarray(v[used], dtype=np.float64),
                                        tri_verts=np.ascontiguousarray(tri, dtype=np.uint64)))
        if shell.status() != m3d.Error.NoError:
            return None
        (cavity if volume < 0 else solid).append(shell)
    union = m3d.Manifold.batch_boolean(solid, m3d.OpType.Add) if solid else m3d.Manifold()
    if cavity:
        union = union - m3d.Manifold.batch_boolean(cavity, m3d.OpType.Add)
    return union


def union_shells(vertices: NDArray[np.float64], faces: NDArray[np.integer]
                 ) -> tuple[NDArray[np.float64], NDArray[np.int64]] | None:
    """The boundary of ``union_solid``: (vertices (k, 3) float64, faces (f, 3) int64,
    outward wound, closed and manifold), in the input's units; None where manifold3d cannot
    read a shell."""
    union = union_solid(vertices, faces)
    if union is None:
        return None
    mesh = union.to_mesh64()
    return (np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3],
            np.asarray(mesh.tri_verts, dtype=np.int64))
