from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from core.stages import TetMesh
from slicer.config import SlicingConfig
from slicer.field import compute_field
from slicer.field_heights import height_stats, layer_heights, stats_of_gradient
from slicer.operators import build_operators
from slicer.solvers import SPDSolver
from tests.slicer.conftest import ring_mesh


def _cfg(**kw: object) -> SlicingConfig:
    return SlicingConfig(**kw)  # type: ignore[arg-type]


def test_planar_is_z(box: TetMesh) -> None:
    res = compute_field(box, _cfg(planar=True, layer_height_mm=0.5))
    assert res.status == "planar"
    np.testing.assert_allclose(res.g, box.vertices[:, 2] - box.vertices[:, 2].min(), atol=0)
    np.testing.assert_allclose(res.gradient, [[0, 0, 1]] * len(res.gradient), atol=1e-12)
    assert res.height.mean == pytest.approx(0.5)
    assert res.height.std < 1e-12
    assert res.delta == pytest.approx(0.5)


@pytest.mark.parametrize("critical", [("bottom", "top"), ("bottom",), ()])
def test_box_gives_linear_field(box: TetMesh, critical: tuple[str, ...]) -> None:
    # Every constraint asks for +z growth, so the exact optimum is g = c * z.
    res = compute_field(box, _cfg(critical=critical, layer_height_mm=0.4))
    assert res.status == "converged"
    grad = res.gradient / np.linalg.norm(res.gradient, axis=1).mean()
    np.testing.assert_allclose(grad, [[0, 0, 1]] * len(grad), atol=1e-6)
    for g in (res.g, res.g0):
        z = box.vertices[:, 2]
        np.testing.assert_allclose(g / g.max(), z / z.max(), atol=1e-6)
    assert res.height.std < 1e-6 and res.height_initial.std < 1e-6
    assert res.height.mean == pytest.approx(0.4)


def test_regions_have_constant_field(ring: TetMesh) -> None:
    res = compute_field(ring, _cfg(critical=("bottom", "top")))
    assert len(res.regions.regions) == 2
    for region in res.regions.regions:
        vals = res.g[region.vertices]
        assert np.ptp(vals) == 0.0
    bottom, top = res.regions.regions
    assert res.g[bottom.vertices[0]] == 0.0  # start surface at the minimum
    assert res.g[top.vertices[0]] == pytest.approx(res.g.max())


def test_iteration_reduces_height_variation(ring: TetMesh) -> None:
    # Wavy critical rim only: layers can follow the rim with an (almost) uniform height, the
    # harmonic start cannot.
    res = compute_field(ring, _cfg(critical=("top:45",), max_iterations=40))
    assert res.status == "converged"
    assert res.iterations >= 2
    assert res.height.std < 0.3 * res.height_initial.std
    assert res.height.cv < 0.05
    assert res.trace.height_std[0] == pytest.approx(res.height_initial.std)
    assert res.trace.height_std[-1] == pytest.approx(res.height.std)
    # O_align settles: the last change is below the convergence threshold.
    o = res.trace.o_align
    assert abs(o[-1] - o[-2]) < 1e-2 * o[-2]
    # The rim is one level set and the field grows towards it.
    rim = res.regions.regions[0]
    assert np.ptp(res.g[rim.vertices]) == 0.0 and res.g[rim.vertices[0]] == res.g.max()


def test_max_iterations_status(ring: TetMesh) -> None:
    res = compute_field(ring, _cfg(critical=("top:45",), max_iterations=1))
    assert res.status == "max_iterations" and res.iterations == 1
    res0 = compute_field(ring, _cfg(critical=("top:45",), max_iterations=0))
    assert res0.status == "no_iterations"
    # Without iterations g is the iteration's start (the harmonic vector field's Poisson
    # solution), not the scalar harmonic baseline G0.
    assert res0.height_start is not None
    assert res0.height.std == pytest.approx(res0.height_start.std)
    assert res0.height_initial.std > res0.height.std
    assert res0.report()["height_std_start_mm"] == pytest.approx(res0.height_start.std)


def test_height_stats_analytic() -> None:
    # Two tets of equal volume with |grad g| = 1 and 2: H = delta and delta/2.
    grad = np.array([[0.0, 0.0, 1.0], [0.0, 2.0, 0.0]])
    vol = np.array([1.0, 1.0])
    h, delta = layer_heights(grad, vol, 0.6)
    # mean (delta + delta/2)/2 = 0.6  ->  delta = 0.8
    assert delta == pytest.approx(0.8)
    np.testing.assert_allclose(h, [0.8, 0.4])
    s = stats_of_gradient(grad, vol, 0.6)
    assert (s.mean, s.std, s.min, s.max) == pytest.approx((0.6, 0.2, 0.4, 0.8))
    assert s.cv == pytest.approx(1 / 3)
    # Scaling the field does not change physical heights.
    assert stats_of_gradient(3 * grad, vol, 0.6) == pytest.approx(s)


def test_field_scale_invariance() -> None:
    small = ring_mesh(nt=24, nz=6)
    big = TetMesh(small.vertices * 10.0, small.tets)
    a = compute_field(small, _cfg(critical=("top:45",), layer_height_mm=0.5))
    b = compute_field(big, _cfg(critical=("top:45",), layer_height_mm=5.0))
    assert b.height.cv == pytest.approx(a.height.cv, rel=1e-5)
    assert b.iterations == a.iterations


def test_solver_backends_agree_and_failures_reported(box: TetMesh) -> None:
    ops = build_operators(box)
    lap = ops.laplacian[1:, 1:] + sp.identity(ops.n_vertices - 1) * 1e-3
    b = np.random.default_rng(0).normal(size=(ops.n_vertices - 1, 3))
    ref = np.linalg.solve(lap.toarray(), b)
    for method in ("cholespy", "amg", "cg", "splu"):
        s = SPDSolver(lap, method=method)
        assert s.backend == method and s.status == "ok"
        x, status = s.solve(b)
        assert status == "ok"
        np.testing.assert_allclose(x, ref, rtol=1e-6, atol=1e-6)
    bad = SPDSolver(-lap, method="cholespy")
    assert not bad.ok and bad.status.startswith("failed")
    x, status = bad.solve(b)
    assert status.startswith("failed") and np.all(np.isnan(x))


def test_report_is_json_ready(ring: TetMesh) -> None:
    import json

    res = compute_field(ring, _cfg(critical=("top:45",), max_iterations=3))
    data = json.loads(json.dumps(res.report()))
    assert data["iterations"] == 3 and data["status"] == "max_iterations"
    assert data["height_mm"]["mean"] == pytest.approx(0.6)
    assert data["height_std_initial_mm"] == pytest.approx(res.height_initial.std)
    assert len(data["height_std_per_iteration_mm"]) == 4


def test_height_stats_on_mesh_matches_result(ring: TetMesh) -> None:
    res = compute_field(ring, _cfg(critical=("top:45",), max_iterations=4))
    for g, expected in ((res.g, res.height), (res.g0, res.height_initial)):
        dist = height_stats(ring, g, 0.6)
        assert dist.summary() == pytest.approx(expected.as_dict())
        assert dist.per_tet.shape == (len(ring.tets),)
        assert float(dist.per_tet @ dist.volume / dist.volume.sum()) == pytest.approx(0.6)
    assert res.trace.height_std[0] == pytest.approx(res.height_initial.std)


def test_two_parts_each_get_a_gauge() -> None:
    from tests.slicer.conftest import box_mesh

    a = box_mesh(n=(2, 2, 3), size=(2.0, 2.0, 3.0))
    verts = np.vstack([a.vertices, a.vertices + np.array([5.0, 0.0, 1.0])])
    tets = np.vstack([a.tets, a.tets + len(a.vertices)])
    res = compute_field(TetMesh(verts, tets), _cfg(critical=("bottom",)))
    assert res.status == "converged"
    assert any("2 connected parts" in n for n in res.notes)
    assert np.all(np.isfinite(res.g))
    grad = res.gradient / np.linalg.norm(res.gradient, axis=1, keepdims=True)
    np.testing.assert_allclose(grad, [[0, 0, 1]] * len(grad), atol=1e-6)
    # Both bottoms are start regions pinned to 0 in their own part.
    assert [float(res.g[r.vertices[0]]) for r in res.regions.regions] == [0.0, 0.0]


def test_touching_regions_share_one_value(box: TetMesh) -> None:
    # The bottom and the +x side share an edge, so g is one constant on both.
    res = compute_field(box, _cfg(critical=("bottom", "normal:1,0,0:10"), max_iterations=3))
    assert len(res.regions.regions) == 2
    both = np.concatenate([r.vertices for r in res.regions.regions])
    assert np.ptp(res.g[both]) == 0.0
    assert np.all(np.isfinite(res.g)) and res.status in ("converged", "max_iterations")


def test_amg_setup_is_reproducible_and_keeps_the_global_rng(box: TetMesh) -> None:
    # pyamg draws its start vectors from np.random: two setups of one matrix must agree to
    # the bit (a job sliced twice from one tet mesh gives the same toolpath), and the
    # caller's generator must come out as it went in
    ops = build_operators(box)
    lap = ops.laplacian[1:, 1:] + sp.identity(ops.n_vertices - 1) * 1e-3
    b = np.random.default_rng(2).normal(size=(ops.n_vertices - 1, 2))
    np.random.seed(7)  # noqa: NPY002 (pyamg's generator)
    expected = np.random.rand()  # noqa: NPY002 (pyamg's generator)
    np.random.seed(7)  # noqa: NPY002 (pyamg's generator)
    first = SPDSolver(lap, method="amg", rtol=1e-4).solve(b)[0]
    assert np.random.rand() == expected  # noqa: NPY002 (pyamg's generator)
    second = SPDSolver(lap, method="amg", rtol=1e-4).solve(b)[0]
    assert np.array_equal(first, second)


def test_iterative_solvers_reorder_large_systems() -> None:
    from tests.slicer.conftest import box_mesh

    ops = build_operators(box_mesh(n=(18, 18, 18), size=(9.0, 9.0, 9.0), jitter=0.2))
    lap = sp.csr_matrix(ops.laplacian[1:, 1:] + sp.identity(ops.n_vertices - 1) * 1e-2)
    rng = np.random.default_rng(1)
    x_true = rng.normal(size=(lap.shape[0], 2))
    b = lap @ x_true
    for method in ("amg", "cg"):
        s = SPDSolver(lap, method=method, rtol=1e-10)
        assert s.backend == method and s._perm is not None  # reordered internally
        x, status = s.solve(b, x0=x_true + 0.01)
        assert status == "ok"
        np.testing.assert_allclose(x, x_true, atol=1e-6)


def test_initial_field_is_scalar_harmonic(ring: TetMesh) -> None:
    # G0: Laplace with g fixed on each region to the region's mean height (min shifted to 0).
    res = compute_field(ring, _cfg(critical=("bottom", "top")))
    ops = res.operators
    bottom, top = res.regions.regions
    fixed = np.zeros(ops.n_vertices, dtype=bool)
    fixed[bottom.vertices] = fixed[top.vertices] = True
    residual = ops.laplacian @ res.g0
    assert np.abs(residual[~fixed]).max() < 1e-8 * np.abs(residual).max()
    top_z = ops.vertices[ops.boundary.faces[top.faces], 2].mean(axis=1)
    area = ops.boundary.area[top.faces]
    assert res.g0[top.vertices[0]] == pytest.approx(float((top_z * area).sum() / area.sum()))
    assert np.ptp(res.g0[bottom.vertices]) == 0.0 and res.g0[bottom.vertices[0]] == 0.0
    # The iteration starts from the harmonic vector field, reported apart.
    assert res.height_start is not None
    assert res.trace.height_std[0] == pytest.approx(res.height_initial.std)
    assert res.height.std <= res.height_start.std * (1 + 1e-9)


def test_tets_without_layer_height_carry_no_weight() -> None:
    # A tet whose vertices all lie on one region has grad g = 0 up to rounding: no height.
    grad = np.array([[0.0, 0.0, 2.0]] * 9 + [[1e-17, 0.0, 0.0]])
    vol = np.ones(10)
    stats = stats_of_gradient(grad, vol, 0.5)
    assert stats.mean == pytest.approx(0.5) and stats.std < 1e-12 and stats.max == 0.5
    h, delta = layer_heights(grad, vol, 0.5)
    assert delta == pytest.approx(1.0) and np.all(np.isfinite(h))


def test_fragment_without_region_grows_from_its_bottom() -> None:
    from tests.slicer.conftest import box_mesh

    a = box_mesh(n=(2, 2, 3), size=(2.0, 2.0, 3.0))
    # A stray single tet (its one bottom face is below the region size limit): no region.
    stray = np.array([[6.0, 0.0, 0.0], [7.0, 0.0, 0.0], [6.0, 1.0, 0.0], [6.0, 0.0, 1.0]])
    verts = np.vstack([a.vertices, stray])
    tets = np.vstack([a.tets, np.arange(4)[None, :] + len(a.vertices)])
    res = compute_field(TetMesh(verts, tets), _cfg(critical=("bottom",)))
    assert len(res.regions.regions) == 1
    assert res.constrained[-1]
    for grad in (res.gradient, res.operators.gradient(res.g0)):
        unit = grad[-1] / np.linalg.norm(grad[-1])
        np.testing.assert_allclose(unit, [0.0, 0.0, 1.0], atol=1e-6)
    assert res.height.std < 1e-6 and res.height_initial.std < 1e-6
