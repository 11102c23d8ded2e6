"""Red refinement of tet meshes and the snap of new boundary vertices onto the surface."""

from __future__ import annotations

from pathlib import Path

import igl
import numpy as np
import pytest
import trimesh

from slicer.config import MeshConfig
from slicer.mesh_io import load_surface
from slicer.refine import boundary_vertices, red_refine, snap_boundary
from slicer.tetrahedralize import orient_positive, quality, tet_volumes, tetrahedralize
from tests.slicer.conftest import box_mesh

REGULAR = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, np.sqrt(3) / 2, 0.0],
                    [0.5, np.sqrt(3) / 6, np.sqrt(2 / 3)]])


def _faces(tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    f = np.sort(tets[:, [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]].reshape(-1, 3), axis=1)
    return np.unique(f, axis=0, return_counts=True)


def test_a_regular_tet_splits_into_8_of_an_eighth_its_volume() -> None:
    v, t = red_refine(REGULAR, np.array([[0, 1, 2, 3]]))
    assert v.shape == (10, 3) and t.shape == (8, 4)
    vol = tet_volumes(v, t)
    assert np.all(vol > 0)
    assert np.allclose(vol, tet_volumes(REGULAR, np.array([[0, 1, 2, 3]]))[0] / 8)
    # the 4 corner tets are regular; the octahedron's 4 keep a radius ratio of ~0.72
    ratio = np.sort([quality(v, t[i : i + 1]).mean_quality for i in range(8)])
    assert np.allclose(ratio[4:], 1.0) and ratio[0] > 0.7


def test_refinement_conforms_and_keeps_volume_and_quality() -> None:
    mesh = box_mesh((3, 2, 2), (6.0, 4.0, 4.0), jitter=0.2, seed=3)
    tets = orient_positive(mesh.vertices, mesh.tets)
    v, t = red_refine(mesh.vertices, tets)
    assert len(t) == 8 * len(tets)
    assert np.all(tet_volumes(v, t) > 0)
    assert tet_volumes(v, t).sum() == pytest.approx(96.0)
    _, counts = _faces(t)
    _, counts0 = _faces(tets)
    assert set(counts) <= {1, 2}  # conforming: every face is shared by at most two tets
    assert np.count_nonzero(counts == 1) == 4 * np.count_nonzero(counts0 == 1)
    assert quality(v, t).mean_quality > 0.8 * quality(mesh.vertices, tets).mean_quality
    assert len(np.unique(t)) == len(v)  # every midpoint is used


def test_new_boundary_vertices_snap_onto_the_surface(tmp_path: Path) -> None:
    # A cube's tets refined, snapped to a sphere through the cube's corners would invert
    # tets at the face centres (they move out by 0.73 of the half-edge): the snap backs off
    # there, moves the rest onto the sphere and never inverts a tet.
    mesh = box_mesh((2, 2, 2), (2.0, 2.0, 2.0))
    v0 = mesh.vertices - 1.0
    v, t = red_refine(v0, orient_positive(v0, mesh.tets))
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=np.sqrt(3))
    candidates = boundary_vertices(t)
    candidates = candidates[candidates >= len(v0)]
    snap = snap_boundary(v, t, candidates, sphere.vertices, sphere.faces)
    assert np.all(tet_volumes(snap.vertices, t) > 0)
    r = np.linalg.norm(snap.vertices[candidates], axis=1)
    distance = np.sqrt(igl.point_mesh_squared_distance(
        v[candidates], sphere.vertices, sphere.faces.astype(np.int64))[0])
    moved_fully = np.isclose(snap.moved_mm, distance) & (distance > 0)
    assert moved_fully.sum() > 0 and snap.backed_off > 0
    assert np.allclose(r[moved_fully], np.sqrt(3), atol=2e-3)
    untouched = np.setdiff1d(np.arange(len(v)), candidates)
    assert np.array_equal(snap.vertices[untouched], v[untouched])


def test_refined_tetrahedralisation_matches_the_direct_one(tmp_path: Path) -> None:
    # (fTetWild shrinks its tets next to the surface of a small solid: the ball is 16 target
    # edges across at fTetWild's coarse size)
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=24.0)
    path = tmp_path / "ball.stl"
    sphere.export(path)
    surface = load_surface(path)
    direct, d_stats = tetrahedralize(surface, MeshConfig(edge_length_mm=2.0))
    refined, r_stats = tetrahedralize(surface, MeshConfig(edge_length_mm=2.0, refine=1))
    assert r_stats.refinements == 1 and r_stats.tets == 8 * r_stats.ftetwild_tets
    assert np.all(tet_volumes(refined.vertices, refined.tets) > 0)
    assert abs(r_stats.volume_error) < 2 * abs(d_stats.volume_error) + 2e-3
    assert r_stats.mean_edge_mm == pytest.approx(d_stats.mean_edge_mm, rel=0.25)
    assert r_stats.mean_quality > 0.7
    # the snapped boundary lies on the sphere's tessellation as closely as the direct one
    b = boundary_vertices(refined.tets)
    radius = np.linalg.norm(refined.vertices[b], axis=1)
    b0 = boundary_vertices(direct.tets)
    assert np.abs(radius - 24.0).mean() <= np.abs(
        np.linalg.norm(direct.vertices[b0], axis=1) - 24.0).mean() + 0.02


def test_auto_refines_large_models_only(tmp_path: Path) -> None:
    from core.errors import InputError
    from slicer.config import load_job
    from slicer.tetrahedralize import refinements

    assert MeshConfig().refine == "auto"
    # ~9.5 tets per edge^3: a 20 mm cube at 2 mm is 9.5k tets, at 1 mm 76k
    assert refinements(MeshConfig(edge_length_mm=2.0), 8000.0) == 0
    assert refinements(MeshConfig(edge_length_mm=1.0), 8000.0) == 1
    assert refinements(MeshConfig(edge_length_mm=1.0, refine=0), 8000.0) == 0
    assert refinements(MeshConfig(edge_length_mm=2.0, refine=2), 8000.0) == 2
    for bad in (4, -1, "twice"):
        with pytest.raises(ValueError, match="refine"):
            MeshConfig(refine=bad)  # type: ignore[arg-type]
    job = tmp_path / "job.toml"
    job.write_text("[mesh]\nrefine = \"twice\"\n")
    with pytest.raises(InputError, match="refine"):
        load_job(job)


@pytest.mark.parametrize("coarse", ["fails", "misses the volume", "fine"])
def test_auto_meshes_directly_where_the_refined_mesh_fails(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path, coarse: str) -> None:
    import slicer.tetrahedralize as T
    from core.errors import InputError

    sphere = trimesh.creation.icosphere(subdivisions=2, radius=24.0)
    path = tmp_path / "ball.stl"
    sphere.export(path)
    surface = load_surface(path)
    real = T.quality(REGULAR, np.array([[0, 1, 2, 3]]))
    calls: list[int] = []

    def fake_mesh(surface: object, config: MeshConfig, n_refine: int, *rest: object) -> tuple:
        calls.append(n_refine)
        if n_refine and coarse == "fails":
            raise InputError("fTetWild produced no tets for ball.stl", "smaller edge")
        error = 0.05 if n_refine and coarse == "misses the volume" else 0.001
        return None, T.TetStats(**{**real.as_dict(), "volume_error": error,
                                   "refinements": n_refine})

    monkeypatch.setattr(T, "_mesh", fake_mesh)
    _, stats = T.tetrahedralize(surface, MeshConfig(edge_length_mm=2.0))  # ~69k tets: auto 1
    if coarse == "fine":
        assert calls == [1] and not stats.refine_fallback
    else:
        assert calls == [1, 0] and stats.refine_fallback and stats.refinements == 0
    calls.clear()
    if coarse == "fails":  # an explicit refine is the user's choice: its failure is reported
        with pytest.raises(InputError, match="no tets"):
            T.tetrahedralize(surface, MeshConfig(edge_length_mm=2.0, refine=1))
        assert calls == [1]
