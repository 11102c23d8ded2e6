"""Map-back of lines from the deformed to the original layer (eqs. 15, 16)."""

from __future__ import annotations

import numpy as np

from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.mapback import (
    barycentric,
    face_normals,
    interpolate,
    map_back,
    point_normals,
    vertex_normals,
)

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


def _sphere_cap(r: float = 20.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A disc mesh lifted onto the sphere |p| = r (radial growth direction)."""
    v, f = disc_mesh(8.0, 1.0)
    z = np.sqrt(r * r - (v[:, :2] ** 2).sum(axis=1))
    p = np.column_stack([v[:, :2], z])
    return p, f, p / r


def test_point_normals_on_a_sphere_follow_the_radius() -> None:
    v, f, grow = _sphere_cap()
    face, bary = _random_points(f, 300, seed=3)
    pts = interpolate(v, f, face, bary)
    n = point_normals(vertex_normals(v, f, grow), f, face_normals(v, f, grow), face, bary)
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    exact = pts / np.linalg.norm(pts, axis=1, keepdims=True)
    # blended vertex normals beat the face normals (facets 1 mm on a 20 mm sphere)
    err = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", n, exact), -1, 1)))
    err_face = np.degrees(np.arccos(np.clip(
        np.einsum("ij,ij->i", face_normals(v, f, grow)[face], exact), -1, 1)))
    assert err.max() < 2.0  # one-sided vertex normals on the rim; 1 mm facets span 2.9 deg
    assert err.mean() < err_face.mean()
    # a flat layer keeps exactly its face normal
    flat, ff = disc_mesh(5.0, 1.0)
    up = np.tile([0.0, 0.0, 1.0], (len(flat), 1))
    fc, bc = _random_points(ff, 50)
    assert np.allclose(point_normals(vertex_normals(flat, ff, up), ff,
                                     face_normals(flat, ff, up), fc, bc), [0, 0, 1])


def test_sliver_face_gives_no_normal_spike() -> None:
    """A needle triangle (as marching tets leave) whose own normal is 60+ degrees off."""
    v, f, grow = _sphere_cap()
    k = int(np.argmin(np.linalg.norm(v[f].mean(axis=1)[:, :2], axis=1)))  # a central face
    a, b, c = (int(i) for i in f[k])
    # split face (a, b, c) at m, a point just inside edge ab (0.002 mm towards c) and 0.01 mm
    # out of the surface: (a, m, c), (m, b, c) and the needle (a, b, m), about 1 mm long,
    # whose plane is tilted far from the layer's; the mesh stays conforming
    mid = 0.5 * (v[a] + v[b])
    radial = mid / np.linalg.norm(mid)
    inward = v[c] - mid
    inward -= (inward @ radial) * radial
    m = mid + 0.002 * inward / np.linalg.norm(inward) + 0.01 * radial
    v2 = np.vstack([v, m])
    g2 = np.vstack([grow, radial])
    new = len(v)
    f2 = np.vstack([np.delete(f, k, axis=0), [[a, new, c], [new, b, c], [a, b, new]]])
    f2 = f2.astype(np.int32)
    fn = face_normals(v2, f2, g2)
    assert np.degrees(np.arccos(fn[-1] @ radial)) > 60.0  # the raw face normal spikes
    face = np.full(5, len(f2) - 1, np.int32)
    bary = np.random.default_rng(1).dirichlet(np.ones(3), 5)
    n = point_normals(vertex_normals(v2, f2, g2), f2, fn, face, bary)
    assert np.all(np.degrees(np.arccos(np.clip(n @ radial, -1, 1))) < 5.0)
