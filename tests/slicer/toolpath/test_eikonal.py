"""Eikonal distance on a layer (slicer.toolpath.eikonal)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import Delaunay

from slicer.toolpath import geodesic
from slicer.toolpath.eikonal import (
    eikonal_distance,
    is_planar,
    planar_boundary_distance,
    points_to_segments,
    surface_distance,
    triangle_update,
)
from slicer.toolpath.surface import boundary_vertices
from tests.slicer.toolpath.pattern_meshes import disc, dome


def _coarse_square(side: float, h: float, seed: int = 0, jitter: float | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """A side x side square in z = 0 with edges about h (Delaunay): uniformly random interior
    points, or with ``jitter`` a square lattice moved by up to jitter * h (closer to the
    triangles marching tets cut)."""
    rng = np.random.default_rng(seed)
    edge = np.linspace(0.0, side, int(np.ceil(side / h)) + 1)
    ring = np.concatenate([np.column_stack([edge, np.zeros_like(edge)]),
                           np.column_stack([edge, np.full_like(edge, side)]),
                           np.column_stack([np.zeros_like(edge), edge]),
                           np.column_stack([np.full_like(edge, side), edge])])
    if jitter is None:
        inner = rng.uniform(0.3 * h, side - 0.3 * h, (int((side / h) ** 2), 2))
    else:
        grid = edge[1:-1]
        inner = np.stack(np.meshgrid(grid, grid), axis=-1).reshape(-1, 2)
        inner = inner + jitter * h * rng.uniform(-1.0, 1.0, inner.shape)
    p = np.unique(np.round(np.concatenate([ring, inner]), 9), axis=0)
    f = Delaunay(p).simplices.astype(np.int64)
    return np.column_stack([p, np.zeros(len(p))]), f


def test_exact_for_straight_boundaries_on_an_irregular_coarse_mesh() -> None:
    v, f = _coarse_square(20.0, 2.0)
    src = np.flatnonzero(boundary_vertices(f, len(v)))
    res = eikonal_distance(v, f, src)
    exact = np.minimum.reduce([v[:, 0], 20.0 - v[:, 0], v[:, 1], 20.0 - v[:, 1]])
    assert res.converged
    err = np.abs(res.distance - exact)
    # exact wherever one wall is nearest within each triangle; only near the diagonals
    # (the medial axis, where two fronts meet) is the distance interpolated across a kink
    off_axis = np.abs(np.abs(v[:, 0] - 10.0) - np.abs(v[:, 1] - 10.0)) > 3.0
    assert err[off_axis].max() < 1e-6
    # there it falls short by at most ~h/2 (a kinked distance interpolated linearly)
    assert err.max() < 1.0
    # the heat method on the same mesh is off by a sizeable part of a line width
    heat = geodesic.boundary_distance(v, f)
    assert np.percentile(np.abs(heat - exact), 90) > 5 * np.percentile(err, 90) + 0.05


def test_annulus_matches_the_radial_distance() -> None:
    v, f = disc(20.0, 0.8, inner=8.0, jitter=0.25)
    d = geodesic.boundary_distance(v, f, backend="eikonal")
    r = np.linalg.norm(v[:, :2], axis=1)
    exact = np.minimum(20.0 - r, r - 8.0)
    assert d.min() == 0.0
    # a curved front is first-order accurate: well under the heat method's error
    assert np.abs(d - exact).max() < 0.15
    assert np.abs(d - exact).max() < np.abs(geodesic.boundary_distance(v, f) - exact).max()


def test_distance_on_a_dome_is_the_geodesic_not_the_chord() -> None:
    v, f = disc(15.0, 0.6)
    v = dome(v, 5.0, 15.0)  # z = 5 (1 - r^2 / 15^2)
    d = geodesic.boundary_distance(v, f, backend="eikonal")
    # half way up (the top, where all fronts meet, is interpolated across the kink)
    top = int(np.argmin(np.abs(np.linalg.norm(v[:, :2], axis=1) - 7.5)))
    r_top = float(np.linalg.norm(v[top, :2]))
    # rim to there along a meridian: the arc length of the parabola from r_top to 15
    r = np.linspace(r_top, 15.0, 20001)
    slope = 2.0 * 5.0 * r / 15.0**2
    meridian = float(np.sum(0.5 * (np.sqrt(1 + slope[1:] ** 2) + np.sqrt(1 + slope[:-1] ** 2))
                            * np.diff(r)))
    assert d[top] == pytest.approx(meridian, rel=0.01)
    assert d[top] > np.hypot(15.0 - r_top, 5.0 - v[top, 2]) + 0.3  # not the straight chord


def test_distance_from_one_loop_of_an_annulus() -> None:
    v, f = disc(20.0, 0.8, inner=8.0, jitter=0.2)
    r = np.linalg.norm(v[:, :2], axis=1)
    outer = np.flatnonzero(np.abs(r - 20.0) < 1e-9)
    d = geodesic.distance_from(v, f, outer, backend="eikonal")
    assert np.abs(d - (20.0 - r)).max() < 0.15


def test_triangle_update_is_the_distance_to_the_opposite_edge() -> None:
    v = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [1.0, 3.0, 0.0]])
    f = np.array([[0, 1, 2]])
    cand, ids = triangle_update(v, f, np.array([0.0, 0.0, np.inf]))
    assert cand[ids == 2].min() == pytest.approx(3.0)  # straight down onto the edge
    # a plane wave arriving along +y: t = y + 1 at the edge's ends -> t_c = 4
    cand, ids = triangle_update(v, f, np.array([1.0, 1.0, np.inf]))
    assert cand[ids == 2].min() == pytest.approx(4.0)
    # a front from the left (t = x): c at x = 1 gets 1 exactly, through the edge's interior
    cand, ids = triangle_update(v, f, np.array([0.0, 4.0, np.inf]))
    assert cand[ids == 2].min() == pytest.approx(np.hypot(1.0, 3.0), abs=1e-9)


def test_unreachable_vertices_stay_infinite_and_no_source_is_no_distance() -> None:
    v, f = _coarse_square(4.0, 1.0)
    v2 = np.concatenate([v, v + np.array([10.0, 0.0, 0.0])])
    f2 = np.concatenate([f, f + len(v)])
    src = np.flatnonzero(boundary_vertices(f, len(v)))
    res = eikonal_distance(v2, f2, src)
    assert np.all(np.isfinite(res.distance[: len(v)]))
    assert np.all(np.isinf(res.distance[len(v):]))
    empty = eikonal_distance(v, f, np.zeros(0, dtype=np.int64))
    assert np.all(np.isinf(empty.distance)) and empty.passes == 0


def test_pass_limit_reports_not_converged_with_an_upper_bound() -> None:
    v, f = _coarse_square(20.0, 1.0)
    src = np.flatnonzero(boundary_vertices(f, len(v)))
    full = eikonal_distance(v, f, src)
    cut = eikonal_distance(v, f, src, max_passes=1)
    assert full.converged and not cut.converged and cut.passes == 1
    assert np.all(cut.distance >= full.distance - 1e-9)


def test_flat_components_get_the_exact_distance_even_on_the_medial_axis() -> None:
    v, f = _coarse_square(20.0, 2.0)
    assert is_planar(v, f)
    d = planar_boundary_distance(v, f)
    exact = np.minimum.reduce([v[:, 0], 20.0 - v[:, 0], v[:, 1], 20.0 - v[:, 1]])
    assert np.abs(d - exact).max() < 1e-9
    # boundary_distance picks it for a flat component: the disc's centre is not cut short
    dv, df = disc(20.0, 2.0, jitter=0.3)
    r = np.linalg.norm(dv[:, :2], axis=1)
    flat = geodesic.boundary_distance(dv, df, backend="eikonal")
    ring = np.max(r[np.isclose(r, r.max())])  # the boundary polygon's vertices
    inside = r < ring * np.cos(np.pi / 32)  # beyond the polygon's chords
    assert np.abs(flat[inside] - (ring * np.cos(np.pi / 63) - r[inside])).max() < 0.05
    centre = int(np.argmin(r))
    propagated = eikonal_distance(dv, df, np.flatnonzero(boundary_vertices(df, len(dv))))
    assert flat[centre] > propagated.distance[centre]


def test_a_curved_component_is_not_planar() -> None:
    v, f = disc(15.0, 1.0)
    assert is_planar(v, f)
    assert not is_planar(dome(v, 2.0, 15.0), f)
    # tilted but flat is still planar
    tilt = v @ np.array([[1.0, 0.0, 0.0], [0.0, 0.8, 0.6], [0.0, -0.6, 0.8]])
    assert is_planar(tilt, f)


def test_curved_disc_centre_is_not_cut_short() -> None:
    v, f = disc(15.0, 1.0)
    v = dome(v, 5.0, 15.0)
    src = np.flatnonzero(boundary_vertices(f, len(v)))
    top = int(np.argmin(np.linalg.norm(v[:, :2], axis=1)))
    r = np.linspace(0.0, 15.0, 20001)
    slope = 2.0 * 5.0 * r / 15.0**2
    meridian = float(np.sum(0.5 * (np.sqrt(1 + slope[1:] ** 2) + np.sqrt(1 + slope[:-1] ** 2))
                            * np.diff(r)))
    propagated = eikonal_distance(v, f, src).distance[top]
    repaired = surface_distance(v, f, src)[top]
    assert repaired >= propagated
    chord = np.linalg.norm(v[src] - v[top], axis=1).min()
    assert repaired >= chord - 0.01 > propagated  # at least the straight line to the rim
    assert repaired <= meridian  # never longer than the surface path


def _jacobi_reference(v: np.ndarray, f: np.ndarray, src: np.ndarray) -> np.ndarray:
    """The fixed point the vectorised way (the solver before session 14): Jacobi passes of
    ``triangle_update`` over every triangle, from Dijkstra's graph distance."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import dijkstra

    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    w = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
    g = sp.coo_matrix((w, (e[:, 0], e[:, 1])), shape=(len(v), len(v))).tocsr()
    t = dijkstra(g.maximum(g.T), directed=False, indices=src, min_only=True)
    t[src] = 0.0
    for _ in range(5000):
        cand, ids = triangle_update(v, f, t)
        new = t.copy()
        np.minimum.at(new, ids, cand)
        new[src] = 0.0
        if not np.any(new < t - 1e-9):
            return new
        t = new
    raise AssertionError("the reference did not converge")


@pytest.mark.parametrize("shape", ["dome", "annulus", "square"])
def test_compiled_solver_reaches_the_jacobi_fixed_point(shape: str) -> None:
    if shape == "dome":
        v, f = disc(15.0, 0.9, jitter=0.3)
        v = dome(v, 5.0, 15.0)
    elif shape == "annulus":
        v, f = disc(20.0, 1.1, inner=8.0, jitter=0.3)
    else:
        v, f = _coarse_square(20.0, 2.0, seed=3)
    f = f.astype(np.int64)
    src = np.flatnonzero(boundary_vertices(f, len(v)))
    res = eikonal_distance(v, f, src)
    assert res.converged
    assert np.abs(res.distance - _jacobi_reference(v, f, src)).max() < 1e-6


def test_a_visit_cap_stops_the_solve_with_an_upper_bound() -> None:
    v, f = _coarse_square(20.0, 1.0, seed=2)
    src = np.flatnonzero(boundary_vertices(f, len(v)))
    full = eikonal_distance(v, f, src)
    capped = eikonal_distance(v, f, src, max_passes=1)
    assert full.converged and not capped.converged
    assert capped.passes == 1
    assert np.all(capped.distance >= full.distance - 1e-9)  # still an upper bound
    assert np.isinf(capped.distance).any() or np.any(capped.distance > full.distance + 1e-6)


def test_points_to_segments_matches_brute_force() -> None:
    rng = np.random.default_rng(5)
    # a polyline (pieces of similar length, like a boundary) and points all around it
    angle = np.sort(rng.uniform(0.0, 2.0 * np.pi, 60))
    ring = np.column_stack([10.0 * np.cos(angle), 7.0 * np.sin(angle), rng.uniform(-1, 1, 60)])
    a, b = ring, np.roll(ring, -1, axis=0)
    x = rng.uniform(-14.0, 14.0, (500, 3))
    ab = b - a
    u = np.clip(np.einsum("pkj,kj->pk", x[:, None, :] - a, ab) / np.einsum("kj,kj->k", ab, ab),
                0.0, 1.0)
    brute = np.linalg.norm(x[:, None, :] - (a + u[..., None] * ab), axis=2).min(axis=1)
    assert np.abs(points_to_segments(x, a, b) - brute).max() < 1e-9
    assert np.all(np.isinf(points_to_segments(x, a[:0], b[:0])))
