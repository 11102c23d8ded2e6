"""Map-back of lines from the deformed to the original layer (eqs. 15, 16)."""

from __future__ import annotations

import numpy as np

from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.mapback import barycentric, face_normals, interpolate, map_back

from .test_build import disc_mesh


def _random_points(faces: np.ndarray, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    face = rng.integers(0, len(faces), n).astype(np.int32)
    bary = rng.dirichlet(np.ones(3), n)
    return face, bary


def test_map_back_to_warped_layer() -> None:
    v, f = disc_mesh(10.0, 1.0)
    face, bary = _random_points(f, 200)
    # the "deformed" layer: same connectivity, squashed and sheared positions
    deformed = v * [0.7, 1.3, 1.0] + [[0.2, 0.0, 0.0]] * v[:, [1, 0, 2]]
    lines = SurfaceLines(interpolate(deformed, f, face, bary), face, bary,
                         np.zeros(200, np.int32), np.array([False]))
    original = v.copy()
    original[:, 2] = 0.05 * (v[:, 0] ** 2)  # a curved original layer
    back = map_back(lines, original, f)
    assert np.array_equal(back.face, face)
    assert np.allclose(back.bary, bary)
    tri = original[f[face]]
    assert np.allclose(back.points, np.einsum("pj,pjk->pk", bary, tri))
    # eq. 15 recovers the coordinates from the mapped point
    assert np.allclose(barycentric(back.points, original, f, face), bary, atol=1e-9)


def test_face_normals_follow_growth_direction() -> None:
    v, f = disc_mesh(5.0, 1.0)
    up = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    n = face_normals(v, f, up)
    assert np.allclose(n, [0, 0, 1])
    # faces wound the other way still get normals along growth
    n2 = face_normals(v, f[:, [0, 2, 1]], up)
    assert np.allclose(n2, [0, 0, 1])
    # growth downwards flips them
    assert np.allclose(face_normals(v, f, -up), [0, 0, -1])


def test_face_normals_on_tilted_plane_are_unit() -> None:
    v, f = disc_mesh(5.0, 1.0)
    rot = np.array([[1, 0, 0], [0, np.cos(0.5), -np.sin(0.5)], [0, np.sin(0.5), np.cos(0.5)]])
    vr = v @ rot.T
    grow = np.tile(rot @ [0, 0, 1.0], (len(v), 1))
    n = face_normals(vr, f, grow)
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    assert np.allclose(n, rot @ [0, 0, 1.0])
