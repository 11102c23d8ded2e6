"""Repair of non-manifold or open surfaces (``mesp slice --repair``) by fTetWild's wrap.

A CAD export or a merged scan is often closed yet non-manifold: bodies touching along an
edge, an internal face left between two parts, shells sharing a seam. ``load_surface``
refuses it (the winding cannot be made consistent around an edge of 3 or more faces).
fTetWild is built for such input: it meshes the space around the triangles and keeps the tets
inside by the generalized winding number, so the boundary of its tet mesh is a closed,
manifold surface within its envelope (``EPSILON`` of the bounding-box diagonal) of the input.
The wrap is coarse (``EDGE_LENGTH_FAC``): only its boundary is used, and its accuracy is the
envelope, not the edge length. Where parts of the wrap touch along an edge or at a point, the
tet boundary is itself non-manifold there: the touching vertices are split into one copy per
part (``split_pinches``), so the parts become separate closed shells. The wrapped surface then
goes through ``load_surface``'s checks like any other, and one note says what changed. An
open surface whose holes a fan cannot close (``slicer.repair``: a wall with a hole, sheets) is
wrapped the same way: the winding number needs no closed input to tell inside from outside.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slicer.shell_split import (
    SPLIT_OFFSET_FAC,
    non_manifold_edges,
    open_edges,
    separate_shells,
)
from slicer.solid_volume import signed_volume
from slicer.tet_geometry import compact, orient_positive

# Target edge length of the wrap, as a fraction of the bounding-box diagonal: coarse, so the
# check that offers --repair stays fast; the boundary's accuracy is the envelope below.
EDGE_LENGTH_FAC = 0.2
# fTetWild's envelope, as a fraction of the bounding-box diagonal (its default).
EPSILON = 1e-3
# Mesh-quality work is not needed for a boundary: few optimisation passes, a loose target.
OPT_ITERATIONS = 5
STOP_ENERGY = 100.0
# The outward faces of a positively oriented tet: face k is opposite vertex k.
_TET_FACES = np.array([(1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1)])


@dataclass(frozen=True)
class Wrap:
    """What ``wrap`` changed.

    Attributes:
        non_manifold_edges: edges used by 3 or more faces in the input.
        open_edges: edges used by one face in the input (fTetWild's winding number closes
            them).
        faces_before: triangles of the input. faces_after: triangles of the wrap.
        volume_before: signed volume of the input, in file units cubed (the sum over its
            faces; counts overlapping shells twice).
        volume_after: volume of the wrap, in file units cubed.
        pinches: vertices of the wrap where parts touch (along an edge or at a point),
            each split into one copy per part.
        bodies: vertex-connected bodies of the input. bodies_wrapped: those given to
            fTetWild (``slicer.body_wrap``: the others are kept as they are).
    """

    non_manifold_edges: int
    open_edges: int
    faces_before: int
    faces_after: int
    volume_before: float
    volume_after: float
    pinches: int
    bodies: int = 1
    bodies_wrapped: int = 1


def boundary_faces(tets: np.ndarray) -> np.ndarray:
    """(f, 3) int64 faces used by exactly one of the positively oriented (T, 4) ``tets``,
    wound counter-clockwise seen from outside."""
    faces = tets[:, _TET_FACES].reshape(-1, 3).astype(np.int64)
    _, inverse, uses = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True,
                                 return_counts=True)
    return faces[uses[inverse.ravel()] == 1]



def wrap(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, Wrap]:
    """The boundary of fTetWild's winding-number tet mesh of ``vertices`` (n, 3) float64
    and ``faces`` (m, 3) int (vertices merged).

    Returns:
        (vertices (k, 3) float64, faces (f, 3) int64 outward wound, the summary), in the
        input's units.
    """
    import pytetwild

    faces = np.asarray(faces, dtype=np.int64)
    points, tets = pytetwild.tetrahedralize(
        np.asarray(vertices, dtype=np.float64), faces.astype(np.int32),
        edge_length_fac=EDGE_LENGTH_FAC, epsilon=EPSILON, num_opt_iter=OPT_ITERATIONS,
        stop_energy=STOP_ENERGY, quiet=True)
    points = np.asarray(points, dtype=np.float64)
    tets = np.asarray(tets, dtype=np.int64)
    if len(tets) == 0:
        return points[:0], np.zeros((0, 3), dtype=np.int64), Wrap(
            non_manifold_edges(faces), open_edges(faces), len(faces), 0,
            signed_volume(np.asarray(vertices, dtype=np.float64), faces), 0.0, 0)
    tets = orient_positive(points, tets)
    out_v, out_f = compact(points, boundary_faces(tets))
    diagonal = float(np.linalg.norm(np.ptp(out_v, axis=0)))
    out_v, out_f, pinches = separate_shells(out_v, out_f, SPLIT_OFFSET_FAC * diagonal)
    return out_v, out_f, Wrap(non_manifold_edges(faces), open_edges(faces), len(faces),
                              len(out_f),
                              signed_volume(np.asarray(vertices, dtype=np.float64), faces),
                              signed_volume(out_v, out_f), pinches)
