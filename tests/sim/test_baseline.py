"""Planar baseline slicer, and planar vs conformal layers on a sphere."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from core.errors import InputError
from core.stages import Pattern, Toolpath
from sim.baseline import (
    VOLUME_MATCHING_BETA,
    PlanarConfig,
    line_parameters,
    planar_toolpath,
    rasterise_section,
    section_segments,
)
from sim.deposition import EllipseMorphology, covering_grid, deposit
from sim.metrics import inspect_deposit


def _box(side: float) -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=[side, side, side])
    box.apply_translation([0.5 * side] * 3)
    return box


def test_section_of_a_box_rasterises_to_its_square() -> None:
    box = _box(4.0)
    seg = section_segments(box.vertices[box.faces], 2.0)
    assert len(seg) == 8  # two triangles per side face
    x = np.arange(-1.0, 5.0, 0.05)
    inside = rasterise_section(seg, x, x)
    assert inside.sum() * 0.05**2 == pytest.approx(16.0, rel=0.02)


def test_overlap_mode_line_parameters() -> None:
    morph = EllipseMorphology(beta=0.5)
    cfg = PlanarConfig(layer_height_mm=0.6, beta=0.5)
    v, w = line_parameters(morph, cfg)
    w_f, h_f = (float(a[0]) for a in morph.filament_size(np.array([v])))
    assert h_f == pytest.approx(0.6 / 0.5, rel=1e-6)
    assert w == pytest.approx(0.5 * w_f, rel=1e-6)
    # At the volume-matching overlap the ink per mm equals the line's W * H.
    v, w = line_parameters(morph, PlanarConfig(layer_height_mm=0.6))
    assert morph.rate_mm3_s / v == pytest.approx(w * 0.6, rel=1e-6)
    assert VOLUME_MATCHING_BETA == pytest.approx(np.sqrt(np.pi) / 2)


def test_box_is_sliced_into_alternating_rasters_with_perimeters() -> None:
    morph = EllipseMorphology(beta=0.7)
    box = _box(6.0)
    tp = planar_toolpath(box.vertices, box.faces, morph,
                         PlanarConfig(layer_height_mm=0.6, beta=0.7, width_mode="volume"))
    assert np.unique(tp.layer).tolist() == list(range(10))
    assert np.allclose(tp.normal, [0.0, 0.0, 1.0])
    assert np.allclose(tp.height, 0.6)
    assert np.all(np.diff(tp.path) >= 0) and np.all(np.diff(tp.layer) >= 0)
    w = float(tp.width[0])
    assert w == pytest.approx(morph.rate_mm3_s / (0.6 * tp.speed[0]), rel=1e-9)
    for k in (0, 1):
        on = (tp.layer == k) & (tp.pattern == Pattern.STRIPE)
        p = tp.position[on]
        lines = [p[tp.path[on] == i] for i in np.unique(tp.path[on])]
        spans = np.array([np.ptp(line, axis=0)[:2] for line in lines])
        along = 0 if k == 0 else 1
        assert np.all(spans[:, along] > 1.0) and np.allclose(spans[:, 1 - along], 0.0)
    # The perimeter runs half a line width inside the faces.
    per = tp.position[(tp.layer == 3) & (tp.pattern == Pattern.CONTOUR)]
    d_face = np.minimum.reduce([per[:, 0], 6.0 - per[:, 0], per[:, 1], 6.0 - per[:, 1]])
    assert np.median(d_face) == pytest.approx(0.5 * w, abs=0.05)


def test_volume_mode_deposits_the_model_volume() -> None:
    morph = EllipseMorphology(beta=0.7)
    box = _box(6.0)
    tp = planar_toolpath(box.vertices, box.faces, morph,
                         PlanarConfig(width_mode="volume", perimeters=0))
    dep = deposit(tp, morph, grid=covering_grid(tp, morph, box.bounds))
    assert dep.deposited_mm3 == pytest.approx(216.0, rel=0.03)


def test_bad_baseline_settings() -> None:
    with pytest.raises(InputError):
        PlanarConfig(beta=0.0)
    with pytest.raises(InputError):
        PlanarConfig(layer_height_mm=-1.0)


def _shells(radius: float, h: float, morph: EllipseMorphology, spacing: float = 0.4
            ) -> Toolpath:
    """Conformal toolpath of a ball: concentric shells of latitude circles, normal radial.

    Shell k (radius (k + 1/2) h) circles the z axis on even shells and the x axis on odd
    ones (staggered); circles are W apart along the meridian, W = C / (h v).
    """
    v = morph.speed_for_height(h / morph.beta)
    w = morph.rate_mm3_s / (h * v)
    pts: list[np.ndarray] = []
    normals: list[np.ndarray] = []
    layers: list[np.ndarray] = []
    paths: list[np.ndarray] = []
    for k in range(round(radius / h)):
        r = (k + 0.5) * h
        axis, e1 = (np.eye(3)[2], np.eye(3)[0]) if k % 2 == 0 else (np.eye(3)[0], np.eye(3)[1])
        e2 = np.cross(axis, e1)
        n_circles = max(1, round(np.pi * r / w))
        for theta in (np.arange(n_circles) + 0.5) * np.pi / n_circles:
            rc = r * np.sin(theta)
            phi = np.linspace(0.0, 2 * np.pi, max(4, int(np.ceil(2 * np.pi * rc / spacing))) + 1)
            p = r * np.cos(theta) * axis + rc * (np.cos(phi)[:, None] * e1
                                                 + np.sin(phi)[:, None] * e2)
            pts.append(p)
            normals.append(p / np.linalg.norm(p, axis=1)[:, None])
            layers.append(np.full(len(p), k))
            paths.append(np.full(len(p), len(paths)))
    n = sum(len(p) for p in pts)
    return Toolpath(position=np.concatenate(pts), normal=np.concatenate(normals),
                    layer=np.concatenate(layers), path=np.concatenate(paths),
                    height=np.full(n, h), width=np.full(n, w), speed=np.full(n, v),
                    extrude=np.ones(n, dtype=bool), pattern=np.zeros(n, dtype=np.int8))


def test_planar_layers_on_a_sphere_err_more_than_conformal_shells() -> None:
    radius, h = 6.0, 1.0
    morph = EllipseMorphology(beta=VOLUME_MATCHING_BETA)
    sphere = trimesh.creation.icosphere(4, radius)
    planar = planar_toolpath(sphere.vertices, sphere.faces, morph,
                             PlanarConfig(layer_height_mm=h, beta=morph.beta,
                                          width_mode="volume"))
    curved = _shells(radius, h, morph)
    errors = {}
    for name, tp in (("planar", planar), ("curved", curved)):
        dep = deposit(tp, morph, grid=covering_grid(tp, morph, sphere.bounds))
        q = inspect_deposit(dep, sphere.vertices, sphere.faces, tp)
        errors[name] = q.surface.stats()
    assert errors["planar"]["mean"] > 1.2 * errors["curved"]["mean"]
    assert errors["planar"]["p95"] > errors["curved"]["p95"]


def test_thin_wall_overlap_over_extrudes_a_solid() -> None:
    # Paper section 3.2 / figure 3(b): W = beta w_f and H = beta h_f with beta = 0.5 put
    # pi / (4 beta^2) ~ 3.1 times the model volume into a solid part.
    morph = EllipseMorphology()
    box = _box(5.0)
    tp = planar_toolpath(box.vertices, box.faces, morph, PlanarConfig(beta=0.5, perimeters=0))
    dep = deposit(tp, morph, grid=covering_grid(tp, morph, box.bounds))
    assert dep.commanded_mm3 / 125.0 == pytest.approx(np.pi / (4 * 0.25), rel=0.06)
    q = inspect_deposit(dep, box.vertices, box.faces, tp)
    assert q.over_deposition > 1.5
    assert q.surface.stats()["mean"] > 1.0


def test_thin_tube_wall_gets_one_centre_line() -> None:
    # A tube wall (1.5 mm) thinner than the volume-mode line (W = 1.885 mm): no perimeter fits,
    # the thin-wall line runs along the middle of the wall and carries W * H per mm.
    morph = EllipseMorphology(beta=0.5)
    r1, r2, height = 6.0, 7.5, 3.0
    tube = trimesh.creation.annulus(r_min=r1, r_max=r2, height=height)
    tube.apply_translation([0.0, 0.0, 0.5 * height])
    cfg = PlanarConfig(layer_height_mm=0.6, beta=0.5, width_mode="volume")
    tp = planar_toolpath(tube.vertices, tube.faces, morph, cfg)
    w, h = float(tp.width[0]), float(tp.height[0])
    assert w > r2 - r1
    r = np.linalg.norm(tp.position[:, :2], axis=1)
    assert np.all(np.abs(r - 0.5 * (r1 + r2)) < 0.1)
    assert np.all(tp.pattern == Pattern.CONTOUR)
    length = sum(np.linalg.norm(np.diff(tp.position[tp.path == i], axis=0), axis=1).sum()
                 for i in np.unique(tp.path))
    assert length * w * h == pytest.approx(tube.volume * w / (r2 - r1), rel=0.05)
    with pytest.raises(InputError):  # without thin walls there is nothing to print
        planar_toolpath(tube.vertices, tube.faces, morph,
                        PlanarConfig(layer_height_mm=0.6, beta=0.5, width_mode="volume",
                                     thin_walls=False))


def test_section_distance_is_exact_where_it_is_read() -> None:
    from scipy import ndimage

    from sim.baseline import _section_distance

    rng = np.random.default_rng(3)
    inside = ndimage.binary_opening(ndimage.gaussian_filter(rng.random((80, 70)), 4) > 0.5)
    inside[30:34, :] = False  # a slot, so some outside points see the section diagonally only
    got = _section_distance(inside)
    full = np.where(inside, ndimage.distance_transform_edt(inside) - 0.5,
                    0.5 - ndimage.distance_transform_edt(~inside))
    near = ndimage.binary_dilation(inside, structure=np.ones((3, 3), dtype=bool))
    assert np.array_equal(got[near], full[near])
    assert np.all(got[~near] <= -1.5 + 1e-12)


def test_a_thick_tube_has_no_thin_wall_and_a_thin_one_has() -> None:
    from sim.baseline import _thin_walls

    n = 161
    x = y = np.linspace(-8.0, 8.0, n)
    r = np.hypot(*np.meshgrid(x, y, indexing="ij"))
    cfg = PlanarConfig()
    thick = (r > 3.0) & (r < 7.0)
    thin = (r > 5.5) & (r < 6.5)
    assert _thin_walls(thick, x, y, 2.0, cfg) == []
    lines = _thin_walls(thin, x, y, 2.0, cfg)
    assert lines and all(np.allclose(np.hypot(*p.T), 6.0, atol=0.1) for p in lines)


def test_hole_distance_bound_is_a_lower_bound() -> None:
    from scipy import ndimage

    from sim.baseline import _hole_distance_bound

    rng = np.random.default_rng(5)
    holes = ndimage.binary_opening(ndimage.gaussian_filter(rng.random((63, 50)), 3) > 0.56)
    exact = ndimage.distance_transform_edt(~holes)
    bound = _hole_distance_bound(holes)
    assert bound.shape == holes.shape
    assert np.all(bound <= exact + 1e-9)
    assert bound.max() > 0.5 * exact.max()  # and not a useless one
