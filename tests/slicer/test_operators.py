from __future__ import annotations

import numpy as np
import pytest

from core.errors import InputError
from core.stages import TetMesh
from slicer.operators import build_operators, orient_tets, signed_volumes
from tests.slicer.conftest import box_mesh, ring_mesh


def test_orientation_fixed_and_volume_exact(box: TetMesh) -> None:
    ops = build_operators(box)
    assert ops.flipped > 0  # the Freudenthal split has both orientations
    assert np.all(signed_volumes(ops.vertices, ops.tets) > 0)
    assert ops.volume.sum() == pytest.approx(8.0**3, rel=1e-12)
    assert ops.degenerate == 0
    tets, flipped = orient_tets(ops.vertices, ops.tets)
    assert flipped == 0 and np.array_equal(tets, ops.tets)


def test_gradient_of_linear_field_is_exact(box: TetMesh) -> None:
    ops = build_operators(box)
    a = np.array([0.3, -1.7, 2.2])
    g = box.vertices @ a + 5.0
    grad = ops.gradient(g)
    assert grad.shape == (ops.n_tets, 3)
    np.testing.assert_allclose(grad, np.broadcast_to(a, grad.shape), atol=1e-12)
    # Row order is tet-major: row 3t + c.
    np.testing.assert_allclose((ops.grad @ g)[3 * 7 + 2], a[2], atol=1e-12)


def test_laplacian_symmetric_psd_constants_in_kernel(box: TetMesh) -> None:
    ops = build_operators(box)
    lap = ops.laplacian
    assert abs(lap - lap.T).max() == 0.0
    np.testing.assert_allclose(lap @ np.ones(ops.n_vertices), 0.0, atol=1e-12)
    eig = np.linalg.eigvalsh(lap.toarray())
    assert eig.min() > -1e-10
    assert np.sum(eig < 1e-10) == 1  # connected mesh: only constants


def test_divergence_is_adjoint_of_gradient(box: TetMesh) -> None:
    ops = build_operators(box)
    rng = np.random.default_rng(3)
    g = rng.normal(size=ops.n_vertices)
    v = rng.normal(size=(ops.n_tets, 3))
    lhs = float((ops.volume[:, None] * ops.gradient(g) * v).sum())
    assert lhs == pytest.approx(float(g @ ops.divergence(v)), rel=1e-12)
    np.testing.assert_allclose(ops.divergence_matrix @ v.ravel(), ops.divergence(v), atol=1e-12)
    dx, dy, dz = ops.divergence_components
    np.testing.assert_allclose(dx @ v[:, 0] + dy @ v[:, 1] + dz @ v[:, 2], ops.divergence(v),
                               atol=1e-12)


def test_face_adjacency_and_boundary(box: TetMesh) -> None:
    ops = build_operators(box)
    # Each tet has 4 faces: 2 * interior + boundary = 4 T.
    assert 2 * len(ops.face_pairs) + len(ops.boundary) == 4 * ops.n_tets
    assert np.all(ops.face_pairs[:, 0] < ops.face_pairs[:, 1])
    assert ops.boundary.area.sum() == pytest.approx(6 * 64.0, rel=1e-12)
    # Outward normals: on a box they are the 6 axis directions, pointing away from the centre.
    centre = ops.vertices[ops.boundary.faces].mean(axis=1) - 4.0
    assert np.all(np.einsum("ij,ij->i", ops.boundary.normal, centre) > 0)
    np.testing.assert_allclose(np.abs(ops.boundary.normal).max(axis=1), 1.0, atol=1e-12)
    # Winding agrees with the stored normal.
    p = ops.vertices[ops.boundary.faces]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert np.all(np.einsum("ij,ij->i", cross, ops.boundary.normal) > 0)
    # Interior face areas: sum of both sides' faces matches the shared face.
    lf = ops.face_laplacian()
    np.testing.assert_allclose(lf @ np.ones(ops.n_tets), 0.0, atol=1e-12)


def test_poisson_reproduces_linear_solution() -> None:
    mesh = box_mesh(n=(3, 4, 5), size=(6.0, 4.0, 5.0), jitter=0.25, seed=2)
    ops = build_operators(mesh)
    a = np.array([0.5, 0.2, 1.0])
    exact = mesh.vertices @ a
    v = np.broadcast_to(a, (ops.n_tets, 3))
    lap = ops.laplacian.toarray()
    rhs = ops.divergence(v)
    # Pin vertex 0 (gauge) and solve the Neumann problem.
    g = np.zeros(ops.n_vertices)
    g[1:] = np.linalg.solve(lap[1:, 1:], rhs[1:] - lap[1:, 0] * exact[0])
    g[0] = exact[0]
    np.testing.assert_allclose(g, exact, atol=1e-9)


def test_curved_mesh_volume_positive() -> None:
    ops = build_operators(ring_mesh())
    assert np.all(ops.volume > 0)
    assert len(ops.boundary) > 0


def test_empty_mesh_is_input_error() -> None:
    with pytest.raises(InputError):
        build_operators(TetMesh(np.zeros((4, 3)), np.zeros((0, 4), dtype=np.int32)))
