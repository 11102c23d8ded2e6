"""The volume of the solid a closed surface bounds, with overlapping shells counted once.

Scans and CAD exports often hold several closed shells that overlap (a head with its eyes
sunk into it, a teapot's spout and handle pushed into its body). The sum of their signed
volumes counts the overlap twice, while the tet mesh (fTetWild's inside test) and so the
layers and the toolpath hold the union: the part then looks short of ink that was never
there (suzanne 1.7 %, teapot 0.5 % at 40 mm). The union is taken with manifold3d
(``union_solid``, whose boundary ``slicer.shell_union`` hands on): shells with positive
volume are joined, cavities cut out of them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

if TYPE_CHECKING:
    import manifold3d as m3d


def signed_volume(vertices: NDArray[np.float64], faces: NDArray[np.integer]) -> float:
    """Sum of the signed tetrahedra origin-face volumes, mm^3 (positive when outward)."""
    tri = vertices[faces]
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6)


def shells(faces: NDArray[np.integer]) -> NDArray[np.int64]:
    """(m,) int64, the shell of each face: faces joined across shared edges (shells that
    only touch at a vertex stay apart)."""
    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return np.zeros(0, dtype=np.int64)
    edges = np.sort(np.stack([f, np.roll(f, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    _, edge_id = np.unique(edges, axis=0, return_inverse=True)
    edge_id = edge_id.ravel()
    face_of = np.repeat(np.arange(len(f)), 3)
    graph = coo_matrix((np.ones(len(face_of)), (face_of, edge_id)),
                       shape=(len(f), int(edge_id.max()) + 1))
    _, label = connected_components((graph @ graph.T).tocsr(), directed=False)
    return np.asarray(label, dtype=np.int64)


def solid_volume(vertices: NDArray[np.float64], faces: NDArray[np.integer]) -> float:
    """Volume of the solid bounded by a closed, outward-oriented surface, mm^3: the union of
    its shells (module docstring). One shell, or shells manifold3d cannot read, give the
    signed volume."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    total = signed_volume(v, f)
    label = shells(f)
    if len(label) == 0 or int(label.max()) == 0:
        return total
    union = union_solid(v, f)
    return total if union is None else float(union.volume())


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
