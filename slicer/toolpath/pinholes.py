"""Pinholes closed: holes in a layer far narrower than a line are no holes to print around.

A curved layer cut from the tet mesh can carry a hole a few hundredths of a millimetre
round (suzanne's top cap: a loop of four edges, 0.19 mm long, where the line is 2.3 mm
wide). No line can keep such a hole open, the lines beside it cover it by their half
width, yet it is a second boundary loop: the component becomes a band between its rim and
the pinhole, its boundary distance falls to zero in the middle of the part, and the lines
are fitted between the two as if they were the walls of a ring. Closing the pinhole (a
fan of triangles over the loop, no new vertex, so every per-vertex field stays valid)
gives the component back its shape. A hole is a pinhole where its perimeter is below
PINHOLE x the line width W at its vertices: its diameter is then under a sixth of W.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from core.stages import LayerMesh
from slicer.extrusion import ExtrusionProfile
from slicer.toolpath.surface import boundary_loops, components

PINHOLE = 0.5  # a hole whose perimeter is below this x W is closed


def pinhole_fill(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                 width: NDArray[np.float64]) -> NDArray[np.int32]:
    """(k, 3) int32, the triangles that close every pinhole of the mesh ``faces``.

    vertices: (n, 3) float64 mm; width: (n,) float64 mm, the line width W per vertex.
    Per connected component, its longest boundary loop is its rim; every other loop
    shorter than PINHOLE x the mean W at its vertices is closed by a fan from its first
    vertex, wound against its boundary edges (the surface stays consistently oriented).
    """
    f = np.asarray(faces, dtype=np.int64)
    fill: list[NDArray[np.int64]] = []
    for comp in components(f):
        # numbered within the component (order kept), so each walk costs its own size
        ids, local = np.unique(f[comp], return_inverse=True)
        loops = [ids[lp] for lp in boundary_loops(local.reshape(-1, 3)) if len(lp) >= 3]
        if len(loops) < 2:
            continue
        length = np.array([np.linalg.norm(vertices[lp] - vertices[np.roll(lp, -1)],
                                          axis=1).sum() for lp in loops])
        rim = int(np.argmax(length))
        for i, lp in enumerate(loops):
            if i != rim and length[i] < PINHOLE * float(np.mean(width[lp])):
                # boundary edge lp[j] -> lp[j + 1]: the fill holds lp[j + 1] -> lp[j]
                j = np.arange(1, len(lp) - 1)
                fill.append(np.column_stack([np.full(len(j), lp[0]), lp[j + 1], lp[j]]))
    if not fill:
        return np.zeros((0, 3), dtype=np.int32)
    return np.concatenate(fill).astype(np.int32)


def close_pinholes(layer: LayerMesh, profile: ExtrusionProfile) -> LayerMesh:
    """``layer`` with its pinholes closed (``pinhole_fill`` at the profile's W of the
    layer's H, raised to the profile's smallest as it is printed); the same value where it
    has none."""
    if len(layer.faces) == 0:
        return layer
    height = np.maximum(layer.height, profile.layer_height_range[0])
    fill = pinhole_fill(layer.vertices, layer.faces, profile.width(height))
    if len(fill) == 0:
        return layer
    faces = np.concatenate([np.asarray(layer.faces, dtype=np.int32), fill])
    return replace(layer, faces=faces)
