"""Topology, Laplacian and direction-field helpers of slicer.toolpath.surface."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import InputError
from slicer.toolpath import surface
from tests.slicer.toolpath.pattern_meshes import disc, dome


def test_components_and_boundary_loops_of_two_annuli() -> None:
    v1, f1 = disc(10.0, 1.5, inner=4.0)
    v2, f2 = disc(6.0, 1.5)
    v = np.concatenate([v1, v2 + np.array([30.0, 0.0, 0.0])])
    f = np.concatenate([f1, f2 + len(v1)])
    comps = surface.components(f)
    assert [len(c) for c in comps] == sorted([len(f1), len(f2)], reverse=True)
    loops = surface.boundary_loops(f)
    assert len(loops) == 3
    radii = sorted(float(np.linalg.norm(v[lp, :2] - v[lp, :2].mean(0), axis=1).mean())
                   for lp in loops)
    assert radii == pytest.approx([4.0, 6.0, 10.0], rel=1e-6)
    # consecutive loop vertices are joined by boundary edges
    be = {tuple(e) for e in surface.boundary_edges(f).tolist()}
    for lp in loops:
        assert all((int(a), int(b)) in be for a, b in zip(lp, np.roll(lp, -1), strict=True))


def test_cotan_laplacian_kills_linear_functions_inside() -> None:
    v, f = disc(8.0, 1.0)
    lap = surface.cotan_laplacian(v, f)
    inner = ~surface.boundary_vertices(f, len(v))
    for coord in (v[:, 0], 2.0 * v[:, 1] + 1.0):
        assert np.abs((lap @ coord)[inner]).max() < 1e-9
    assert np.abs(lap @ np.ones(len(v))).max() < 1e-9
    robust = surface.cotan_laplacian(v, f, robust=True)
    assert np.abs(robust @ np.ones(len(v))).max() < 1e-9
    assert (robust - robust.T).count_nonzero() == 0 or abs(robust - robust.T).max() < 1e-9


def test_face_gradient_of_linear_function_on_curved_surface_is_tangent() -> None:
    v, f = disc(8.0, 1.0)
    v = dome(v, 3.0, 8.0)
    g = surface.face_gradient(v, f, v[:, 0])
    n, _ = surface.face_normals(v, f)
    assert np.abs(np.einsum("ij,ij->i", g, n)).max() < 1e-9
    flat_v, flat_f = disc(8.0, 1.0)
    gf = surface.face_gradient(flat_v, flat_f, 3.0 * flat_v[:, 0] - flat_v[:, 1])
    assert np.allclose(gf, [3.0, -1.0, 0.0])


def test_stripe_direction_is_unit_tangent_and_radial_on_a_disc() -> None:
    v, f = disc(10.0, 1.0)
    r = np.linalg.norm(v[:, :2], axis=1)
    d = surface.stripe_direction(v, f, 10.0 - r)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    cen = v[f].mean(axis=1)
    far = np.linalg.norm(cen[:, :2], axis=1) > 3.0
    radial = cen[far, :2] / np.linalg.norm(cen[far, :2], axis=1)[:, None]
    assert np.abs(np.einsum("ij,ij->i", d[far, :2], radial)).min() > 0.98


def test_bad_mesh_raises_input_error() -> None:
    with pytest.raises(InputError):
        surface.check_mesh(np.zeros((3, 3)), np.array([[0, 1, 5]]))


def test_parallel_direction_is_the_long_axis_in_each_face() -> None:
    v, f = disc(10.0, 0.8)
    v = dome(v, 2.0, 10.0)
    v[:, 0] *= 1.5  # longest along x
    d = surface.parallel_direction(v, f)
    assert d is not None
    normal, _ = surface.face_normals(v, f)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    assert np.abs(np.einsum("ij,ij->i", d, normal)).max() < 1e-9  # tangent
    assert np.median(np.abs(d[:, 0])) > 0.95


def test_parallel_direction_refuses_a_cap_curving_round() -> None:
    # a hemisphere: its rim faces stand parallel to any horizontal axis (the projected field
    # would be singular there)
    v, f = disc(10.0, 0.8)
    r = np.linalg.norm(v[:, :2], axis=1)
    v[:, 2] = np.sqrt(np.maximum(10.0**2 - r**2, 0.0))
    assert surface.parallel_direction(v, f) is None
