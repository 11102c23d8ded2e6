"""Slab volumes of the slicing field and layer heights matched to them."""

from __future__ import annotations

import numpy as np
import pytest

from core.stages import Field
from slicer.layers import extract_layers, iso_surfaces, slab_bounds
from slicer.operators import build_operators
from slicer.slabs import SCALE_LIMITS, height_integral, slab_height_scale, slab_volumes
from tests.slicer.conftest import box_mesh


def _cube_tets() -> tuple[np.ndarray, np.ndarray]:
    """The unit cube as 6 positively oriented tets around the diagonal (0,0,0)-(1,1,1)."""
    v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
    idx = {tuple(p): i for i, p in enumerate(v.astype(int))}
    tets = []
    for perm in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)):
        p = np.zeros(3, dtype=int)
        chain = [idx[tuple(p)]]
        for axis in perm:
            p[axis] = 1
            chain.append(idx[tuple(p)])
        tets.append(chain)
    return v, np.array(tets)


def test_slab_volumes_of_a_linear_field_on_a_cube() -> None:
    v, t = _cube_tets()
    # g = z: slabs of a unit square, thickness = bound spacing; a tie-heavy case (g takes
    # only two values per tet edge direction)
    b = np.array([-1.0, 0.1, 0.35, 0.5, 0.9, 2.0])
    assert np.allclose(slab_volumes(v, t, v[:, 2], b), [0.1, 0.25, 0.15, 0.4, 0.1], atol=1e-7)
    # g = x + y + z: volume below s is s^3 / 6 for s <= 1 (a corner tet), 1/2 at s = 3/2
    g = v.sum(axis=1)
    below = slab_volumes(v, t, g, np.array([0.0, 0.6, 1.0, 1.5, 3.0]))
    assert np.allclose(np.cumsum(below), [0.6**3 / 6, 1 / 6, 0.5, 1.0], atol=1e-7)


def test_slab_volumes_match_sampling_on_a_random_tet() -> None:
    rng = np.random.default_rng(3)
    v = rng.normal(size=(4, 3))
    t = np.array([[0, 1, 2, 3]])
    g = rng.normal(size=4)
    b = np.linspace(g.min() - 0.1, g.max() + 0.1, 7)
    vol = abs(np.linalg.det(v[1:] - v[0])) / 6.0
    exact = slab_volumes(v, t, g, b)
    # points uniform in the tet: barycentric weights ~ Dirichlet(1, 1, 1, 1); g is linear
    w = rng.dirichlet(np.ones(4), 400_000)
    sampled = np.histogram(w @ g, bins=b)[0] / len(w) * vol
    assert exact.sum() == pytest.approx(vol, rel=1e-9)
    assert np.allclose(exact, sampled, atol=0.01 * vol)


def test_height_scale_is_the_slab_over_the_integral_within_limits() -> None:
    integral = np.array([10.0, 10.0, 10.0, 0.0, 10.0])
    slab = np.array([10.0, 8.0, 30.0, 5.0, 0.0])
    assert np.allclose(slab_height_scale(integral, slab), [1.0, 0.8, SCALE_LIMITS[1], 1.0, 1.0])


def test_a_linear_field_needs_no_height_correction() -> None:
    mesh = box_mesh((4, 4, 6), (8.0, 8.0, 6.0))
    ops = build_operators(mesh)
    field = Field(g=mesh.vertices[:, 2].copy(), iso=np.array([0.5, 1.5, 2.5, 3.5, 4.5, 5.5]))
    ext = extract_layers(mesh, field)
    assert np.allclose(ext.height_scale, 1.0, atol=1e-6)
    assert np.allclose(ext.layers.vertex_height, 1.0, atol=1e-6)
    raw = iso_surfaces(ops, field)
    assert np.allclose(height_integral(raw.vertices, raw.faces, raw.face_layer,
                                       raw.vertex_height, 6), 64.0, rtol=1e-9)


def test_heights_match_the_slabs_where_the_gradient_changes_across_them() -> None:
    """g = z^2 on a 6 mm box: |grad g| grows with z, so at a layer (the middle of its g-slab,
    above the slab's physical middle) H = slab / |grad g| falls short of the slab's thickness,
    by 30 % on the bottom one (z in [0, 2.45], the layer at z = 1.73: H = 1.73); after
    matching, the integral of H over each layer is the slab's exact volume."""
    mesh = box_mesh((4, 4, 12), (8.0, 8.0, 6.0))
    ops = build_operators(mesh)
    g = mesh.vertices[:, 2] ** 2
    bounds = np.linspace(0.0, 36.0, 7)
    field = Field(g=g, iso=0.5 * (bounds[1:] + bounds[:-1]))
    raw = iso_surfaces(ops, field)
    before = height_integral(raw.vertices, raw.faces, raw.face_layer, raw.vertex_height, 6)
    slab = slab_volumes(ops.vertices, ops.tets, g, slab_bounds(field.iso, 0.0, 36.0))
    # the exact slabs: 64 mm^2 x (sqrt(b_k+1) - sqrt(b_k)), up to the linear interpolation
    assert np.allclose(slab, 64.0 * np.diff(np.sqrt(bounds)), rtol=0.02)
    assert before[0] < 0.75 * slab[0]
    ext = extract_layers(mesh, field)
    after = height_integral(ext.layers.vertices, ext.layers.faces, ext.layers.face_layer,
                            ext.layers.vertex_height, 6)
    assert after == pytest.approx(slab, rel=1e-9)
    assert np.allclose(ext.height_scale, slab / before)
    # the correction is the layer's own: directions and geometry are unchanged
    assert np.array_equal(ext.layers.vertices, raw.vertices)
    assert np.array_equal(ext.layers.vertex_direction, raw.vertex_direction)
