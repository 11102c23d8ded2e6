"""Tetrahedralisation with fTetWild and the tet quality measures, on tiny solids."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from core.errors import InputError
from slicer.config import MeshConfig
from slicer.mesh_io import Surface, load_surface
from slicer.tetrahedralize import (
    _grid_tets,
    compact,
    orient_positive,
    quality,
    sizing_field,
    tet_volumes,
    tetrahedralize,
)

REGULAR = np.array(
    [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.5, np.sqrt(3) / 2, 0.0],
        [0.5, np.sqrt(3) / 6, np.sqrt(2 / 3)],
    ]
)


@pytest.fixture(scope="module")
def cube_surface(tmp_path_factory: pytest.TempPathFactory) -> Surface:
    box = trimesh.creation.box(extents=(20.0, 20.0, 20.0))
    path = tmp_path_factory.mktemp("cube") / "cube.stl"
    box.export(path)
    return load_surface(path)


@pytest.fixture(scope="module")
def cube_tets(cube_surface: Surface) -> tuple:
    return tetrahedralize(cube_surface, MeshConfig(edge_length_mm=5.0))


def test_regular_tet_quality() -> None:
    stats = quality(REGULAR, np.array([[0, 1, 2, 3]]), 1.0 / (6.0 * np.sqrt(2.0)))
    assert stats.min_dihedral_deg == pytest.approx(np.degrees(np.arccos(1 / 3)))
    assert stats.max_dihedral_deg == pytest.approx(stats.min_dihedral_deg)
    assert stats.mean_quality == pytest.approx(1.0)
    assert stats.mean_edge_mm == pytest.approx(1.0)
    assert stats.sliver_fraction == 0.0
    assert stats.volume_error == pytest.approx(0.0, abs=1e-12)


def test_flat_sliver_has_low_quality() -> None:
    sliver = REGULAR.copy()
    sliver[3, 2] = 1e-3  # apex almost in the base plane
    stats = quality(sliver, np.array([[0, 1, 2, 3]]))
    assert stats.worst_quality < 0.02
    assert stats.min_dihedral_deg < 1.0
    assert stats.sliver_fraction == 1.0


def test_right_corner_tet_dihedrals() -> None:
    corner = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    stats = quality(corner, np.array([[0, 1, 2, 3]]))
    # Three right angles at the origin edges, arccos(1/sqrt(3)) = 54.7 deg at the others.
    assert stats.max_dihedral_deg == pytest.approx(90.0)
    assert stats.min_dihedral_deg == pytest.approx(np.degrees(np.arccos(1 / np.sqrt(3))))


def test_orient_and_compact() -> None:
    points = np.vstack([REGULAR, [[9.0, 9.0, 9.0]]])
    tets = np.array([[0, 2, 1, 3]])  # negative
    assert tet_volumes(points, tets)[0] < 0
    fixed = orient_positive(points, tets)
    assert tet_volumes(points, fixed)[0] > 0
    kept, renumbered = compact(points, np.array([[4, 0, 2, 1]]))
    np.testing.assert_array_equal(kept, points[[0, 1, 2, 4]])
    np.testing.assert_array_equal(renumbered, [[3, 0, 2, 1]])


def test_grid_tets_fill_the_box() -> None:
    counts = np.array([2, 3, 1])
    axes = [np.arange(c + 1, dtype=float) for c in counts]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    tets = _grid_tets(counts)
    volumes = tet_volumes(grid, tets)
    assert len(tets) == 6 * 6
    assert np.abs(volumes).sum() == pytest.approx(6.0)
    assert np.all(np.abs(volumes) == pytest.approx(1.0 / 6.0))


def test_cube_at_5mm(cube_surface: Surface, cube_tets: tuple) -> None:
    mesh, stats = cube_tets
    volumes = tet_volumes(np.asarray(mesh.vertices), np.asarray(mesh.tets))
    assert np.all(volumes > 0)
    assert volumes.sum() == pytest.approx(8000.0, rel=0.01)
    assert stats.volume_error == pytest.approx(0.0, abs=0.01)
    assert stats.tets == len(mesh.tets) and stats.vertices == len(mesh.vertices)
    # every vertex is used; the mesh stays inside the cube's envelope
    assert np.unique(mesh.tets).size == len(mesh.vertices)
    lo, hi = np.asarray(mesh.vertices).min(axis=0), np.asarray(mesh.vertices).max(axis=0)
    assert lo == pytest.approx(cube_surface.vertices.min(axis=0), abs=0.1)
    assert hi == pytest.approx(cube_surface.vertices.max(axis=0), abs=0.1)
    assert 2.0 < stats.mean_edge_mm < 12.0
    assert stats.min_dihedral_deg > 1.0 and 0.0 < stats.worst_quality <= stats.mean_quality <= 1.0


def test_graded_sizing_field_keeps_target_near_solid(cube_surface: Surface) -> None:
    points, tets, values = sizing_field(cube_surface, 2.0, grading=0.5)
    assert tets.min() >= 0 and tets.max() < len(points)
    assert np.all(values >= 2.0)
    inside = np.all((points > -10.0) & (points < 10.0), axis=1)
    assert np.all(values[inside] == 2.0)
    assert values.max() > 2.0  # it does grow far outside


def test_graded_cube_is_still_a_cube(cube_surface: Surface) -> None:
    mesh, stats = tetrahedralize(cube_surface, MeshConfig(edge_length_mm=5.0), grading=0.5)
    assert np.all(tet_volumes(np.asarray(mesh.vertices), np.asarray(mesh.tets)) > 0)
    assert stats.volume_error == pytest.approx(0.0, abs=0.01)


def test_absurd_edge_length_is_refused(cube_surface: Surface, tmp_path: Path) -> None:
    big = Surface(cube_surface.vertices * 100.0, cube_surface.faces, tmp_path / "big.stl")
    with pytest.raises(InputError, match="larger --edge-length"):
        tetrahedralize(big, MeshConfig(edge_length_mm=0.05))


def test_ftetwild_failure_is_an_input_error(
    cube_surface: Surface, monkeypatch: pytest.MonkeyPatch
) -> None:
    import pytetwild

    def broken(*args: object, **kwargs: object) -> None:
        raise RuntimeError("envelope check failed")

    monkeypatch.setattr(pytetwild, "tetrahedralize", broken)
    with pytest.raises(InputError) as info:
        tetrahedralize(cube_surface, MeshConfig(edge_length_mm=5.0))
    assert "envelope check failed" in info.value.problem and info.value.fix


def test_empty_ftetwild_output_is_an_input_error(
    cube_surface: Surface, monkeypatch: pytest.MonkeyPatch
) -> None:
    import pytetwild

    def empty(*args: object, **kwargs: object) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros((0, 3)), np.zeros((0, 4), dtype=np.int32)

    monkeypatch.setattr(pytetwild, "tetrahedralize", empty)
    with pytest.raises(InputError, match="no tets"):
        tetrahedralize(cube_surface, MeshConfig(edge_length_mm=5.0))


def test_no_debug_files_in_working_directory(
    cube_surface: Surface, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    tetrahedralize(cube_surface, MeshConfig(edge_length_mm=5.0))
    assert list(tmp_path.iterdir()) == []
