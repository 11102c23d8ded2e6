"""The nearest layer point: analytic cases on a flat square of two triangles."""

from __future__ import annotations

import numpy as np

from slicer.toolpath.layer_nearest import face_tree, inside_barycentric, nearest_on_layer

V = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 10.0, 0.0], [0.0, 10.0, 0.0]])
F = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)


def test_a_point_above_the_layer_lands_below_it_on_its_face() -> None:
    p = np.array([[7.0, 2.0, 3.0], [2.0, 7.0, -1.5]])
    q, face = nearest_on_layer(p, V, F, k=2)
    np.testing.assert_allclose(q, [[7.0, 2.0, 0.0], [2.0, 7.0, 0.0]], atol=1e-12)
    assert face.tolist() == [0, 1]
    bary = inside_barycentric(q, V, F, face.astype(np.int32))
    np.testing.assert_allclose(bary.sum(axis=1), 1.0)
    np.testing.assert_allclose(np.einsum("pk,pkj->pj", bary, V[F[face]]), q, atol=1e-12)


def test_a_point_beside_the_layer_lands_on_its_edge_and_a_kept_tree_gives_the_same() -> None:
    p = np.array([[12.0, 5.0, 0.0]])
    q, face = nearest_on_layer(p, V, F, k=2)
    np.testing.assert_allclose(q, [[10.0, 5.0, 0.0]], atol=1e-12)
    q2, face2 = nearest_on_layer(p, V, F, k=2, tree=face_tree(V, F))
    np.testing.assert_array_equal(q, q2)
    np.testing.assert_array_equal(face, face2)
    bary = inside_barycentric(q, V, F, face.astype(np.int32))
    assert (bary >= 0).all() and abs(bary.sum() - 1.0) < 1e-12
