"""Wrap only the bodies that need it: fTetWild's time grows with the faces it is given.

A CAD export of an assembly holds many bodies (cycloidal.ply: 100), of which a few touch
along an edge or carry an open sheet. A body that is closed and manifold on its own (every
edge used by exactly two of its faces) is already a solid: it is kept face for face, and only
the bodies with an open or non-manifold edge (vertex-connected, so bodies touching at a point
stay together) go through ``winding_repair.wrap``. The kept bodies and the wrap are one
surface again; where they overlap, ``load_surface`` counts the overlap once, as for any
multi-body file.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from slicer.solid_volume import signed_volume
from slicer.tet_geometry import compact
from slicer.winding_repair import Wrap, wrap


def troubled_faces(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, int, int]:
    """Which faces belong to a body with an open or non-manifold edge.

    Args:
        faces: (m, 3) int, vertices merged. n_vertices: vertex count.

    Returns:
        ((m,) bool, bodies, bodies troubled): bodies are the vertex-connected sets of faces.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    faces = np.asarray(faces, dtype=np.int64)
    directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    graph = coo_matrix((np.ones(len(directed)), (directed[:, 0], directed[:, 1])),
                       shape=(n_vertices, n_vertices))
    bodies, label = connected_components(graph, directed=False)
    body = label[faces[:, 0]]  # (m,)
    _, edge_id, uses = np.unique(np.sort(directed, axis=1), axis=0, return_inverse=True,
                                 return_counts=True)
    bad_face = (uses[edge_id.ravel()] != 2).reshape(-1, 3).any(axis=1)
    bad_body = np.zeros(bodies, dtype=bool)
    bad_body[body[bad_face]] = True
    used = np.unique(body)
    return bad_body[body], len(used), int(np.count_nonzero(bad_body[used]))


def wrap_troubled(vertices: np.ndarray, faces: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, Wrap]:
    """``winding_repair.wrap`` of the troubled bodies of ``vertices`` (n, 3) float64 and
    ``faces`` (m, 3) int, the other bodies appended as they are.

    Returns:
        (vertices (k, 3) float64, faces (f, 3) int64, the summary of the whole surface);
        no faces where the wrap finds no inside.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    troubled, bodies, wrapped_bodies = troubled_faces(faces, len(vertices))
    if troubled.all() or not troubled.any():
        out_v, out_f, summary = wrap(vertices, faces)
        return out_v, out_f, replace(summary, bodies=bodies, bodies_wrapped=bodies)
    bad_v, bad_f = compact(vertices, faces[troubled])
    out_v, out_f, part = wrap(bad_v, bad_f)
    whole = replace(part, faces_before=len(faces),
                    volume_before=signed_volume(vertices, faces), bodies=bodies,
                    bodies_wrapped=wrapped_bodies)
    if not len(out_f):
        return out_v, out_f, replace(whole, faces_after=0, volume_after=0.0)
    kept_v, kept_f = compact(vertices, faces[~troubled])
    all_v = np.vstack([out_v, kept_v])
    all_f = np.vstack([out_f, kept_f + len(out_v)])
    return all_v, all_f, replace(whole, faces_after=len(all_f),
                                 volume_after=signed_volume(all_v, all_f))
