"""Stripes printed as wide as their local spacing: a fan of rays and radial stripes on a disc."""

from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay

from core.stages import Layers, Toolpath
from slicer.toolpath import geodesic, surface
from slicer.toolpath.coverage import layer_coverage
from slicer.toolpath.isolines import iso_lines
from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.mapback import interpolate
from slicer.toolpath.stripe_width import side_gaps, stripe_width_scale
from slicer.toolpath.stripes import stripe_lines
from tests.slicer.toolpath.pattern_meshes import disc, flat_mesh


def _sector(r0: float, r1: float, half_angle: float, h: float
            ) -> tuple[np.ndarray, np.ndarray]:
    """Flat annular sector r0..r1, |angle| <= half_angle (rad), edges about h mm."""
    pts = []
    for r in np.arange(r0, r1 + 0.5 * h, h):
        n = max(int(np.ceil(2 * half_angle * r / h)), 2)
        a = np.linspace(-half_angle, half_angle, n + 1)
        pts.append(r * np.column_stack([np.cos(a), np.sin(a)]))
    p = np.concatenate(pts)
    return flat_mesh(p, Delaunay(p).simplices)


def _as_toolpath(lines: SurfaceLines, width: np.ndarray) -> Toolpath:
    """Each line its own extruding path at ``width`` ((P,) mm)."""
    n = len(lines.points)
    return Toolpath(position=lines.points, normal=np.tile([0.0, 0.0, 1.0], (n, 1)),
                    layer=np.zeros(n, np.int32), path=lines.line.astype(np.int32),
                    height=np.full(n, 0.6), width=width, speed=np.full(n, 5.0),
                    extrude=np.ones(n, bool), pattern=np.ones(n, np.int8))


def test_a_fan_of_rays_is_printed_as_wide_as_it_spreads() -> None:
    # rays 0.15 rad apart from r = 6 to 16 mm: the spacing grows from 0.9 to 2.4 mm; each
    # inner ray's width follows r x 0.15 (between its two neighbours)
    v, f = _sector(6.0, 16.0, 0.5, 0.5)
    angle = np.arctan2(v[:, 1], v[:, 0])
    step = 0.15
    lines = iso_lines(v, f, angle, np.linspace(-3 * step, 3 * step, 7))
    spacing = 1.6
    dist = geodesic.boundary_distance(v, f)
    scale = stripe_width_scale(v, f, lines, dist, spacing)
    at = interpolate(scale, f, lines.face, lines.bary)
    r = np.linalg.norm(lines.points[:, :2], axis=1)
    ray = np.rint(np.arctan2(lines.points[:, 1], lines.points[:, 0]) / step)
    inner = (np.abs(ray) <= 2) & (r > 7.0) & (r < 15.0)
    expected = np.clip(r * step / spacing, 0.5, 1.5)
    rel = np.abs(at[inner] - expected[inner]) / expected[inner]
    assert np.percentile(rel, 90) < 0.06 and rel.max() < 0.2
    # the two gaps of an inner ray are its spacing on either side
    fn, _ = surface.face_normals(v, f)
    left, right = side_gaps(lines, fn[lines.face], 2.0 * spacing)
    assert np.allclose(left[inner & (r > 10)], right[inner & (r > 10)], rtol=0.05)


def test_radial_stripes_as_wide_as_their_spacing_cover_a_disc_better() -> None:
    # radial stripes on a 16 mm disc at W = 2.33 mm (the hemisphere's layers): printed at
    # one width they leave the wedges between diverging stripes bare and cover converging
    # ones twice; printed as wide as their spacing both shrink
    v, f = disc(16.0, 0.8, jitter=0.2)
    w = 2.33
    dist = geodesic.boundary_distance(v, f)
    lines = stripe_lines(v, f, surface.stripe_direction(v, f, dist), w)
    scale = stripe_width_scale(v, f, lines, dist, w)
    layers = Layers(v, f.astype(np.int64), np.zeros(len(f), np.int64), np.full(len(v), 0.6),
                    np.tile([0.0, 0.0, 1.0], (len(v), 1)))
    flat = layer_coverage(layers, _as_toolpath(lines, np.full(len(lines.points), w)),
                          samples_per_w2=40.0, max_samples=20_000)
    scaled = layer_coverage(
        layers, _as_toolpath(lines, w * interpolate(scale, f, lines.face, lines.bary)),
        samples_per_w2=40.0, max_samples=20_000)
    assert scaled.overlap[0] < 0.3 * flat.overlap[0]
    assert scaled.gap[0] + scaled.overlap[0] < 0.75 * (flat.gap[0] + flat.overlap[0])
    assert np.all((scale >= 0.5) & (scale <= 1.5))
