"""Wall thickness of a surface: how far inwards the solid reaches from each point.

A wall thinner than the line the toolpath lays cannot be printed at its size: one line over
it deposits several times its volume, and no stripe or ring fits. The preflight
(``planner.preflight``) answers this before a slice of minutes. The measure is the length of
the ray shot inwards along the face normal from points spread evenly over the area (libigl's
AABB tree): the wall's thickness where the wall is flat. Only standing walls count (normal
within 45 deg of horizontal): with the layers following the bottom, their lines run across
those walls, while a flat plate's thickness is spanned by layers, not lines. Near a
re-entrant edge the ray meets the neighbouring face early, so a few percent of a machined
part reads thin without being so: shares are of area, and a problem is a large share.
"""

from __future__ import annotations

from typing import NamedTuple

import igl
import numpy as np
import trimesh

from core.tolerance import tol
from slicer.mesh_io import Surface

SAMPLES = 4000  # points on the surface, area-weighted: a 1 % share is 40 points
STANDING = np.cos(np.radians(45.0))  # |normal_z| below this: a standing wall


class WallThickness(NamedTuple):
    """Thickness sampled over a surface.

    Attributes:
        thickness: (n,) float64, mm, inward ray length from each standing-wall sample (inf
            where the ray left the solid without a hit: a hole or a flipped patch).
        size_mm: float, mm, the surface's largest extent when measured.
    """

    thickness: np.ndarray
    size_mm: float

    def share_below(self, width_mm: float) -> float:
        """Share of the standing-wall area (0-1) thinner than ``width_mm`` (0 if none)."""
        return float(np.mean(self.thickness < width_mm)) if len(self.thickness) else 0.0

    def quantile(self, share: float) -> float:
        """The thickness (mm) below which ``share`` (0-1) of the standing-wall area lies."""
        return float(np.quantile(self.thickness, share)) if len(self.thickness) else np.inf

    def scaled(self, factor: float) -> WallThickness:
        """The same part scaled uniformly by ``factor`` (thickness scales with it)."""
        return WallThickness(self.thickness * factor, self.size_mm * factor)


def _area_samples(surface: Surface, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) points, mm, spread over the area, and (n, 3) unit outward normals of their faces."""
    mesh = trimesh.Trimesh(surface.vertices, surface.faces, process=False)
    points, face = trimesh.sample.sample_surface(mesh, n, seed=seed)
    return np.asarray(points), mesh.face_normals[face]


def wall_thickness(surface: Surface, samples: int = SAMPLES, seed: int = 0) -> WallThickness:
    """The inward ray length at the standing-wall points among ``samples`` area-weighted
    points of ``surface`` (seeded: the same surface gives the same answer)."""
    V = np.ascontiguousarray(surface.vertices, dtype=np.float64)
    F = np.ascontiguousarray(surface.faces, dtype=np.int64)
    size = float(np.ptp(V, axis=0).max())
    points, normal = _area_samples(surface, samples, seed)
    standing = np.abs(normal[:, 2]) < STANDING
    points, normal = points[standing], normal[standing]
    if not len(points):
        return WallThickness(np.zeros(0), size)
    start = points - normal * (tol.on_surface * size)  # just inside: not the face itself
    tree = igl.AABB()
    tree.init(V, F)
    hit, t, _ = tree.intersect_ray_first(V, F, np.ascontiguousarray(start),
                                         np.ascontiguousarray(-normal))
    return WallThickness(np.where(hit >= 0, t, np.inf), size)
