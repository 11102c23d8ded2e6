"""Loading surfaces and tet meshes: every bad file is a one-line InputError."""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
import pytest
import trimesh

from core.errors import InputError
from core.stages import TetMesh
from slicer.config import ModelConfig
from slicer.mesh_io import load_surface, load_tet_mesh, write_tet_mesh
from slicer.surface_refusal import SurfaceReason, SurfaceRefused
from slicer.tet_geometry import tet_volumes


def _box(size: float = 20.0) -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=(size, size, size))
    box.apply_translation([size / 2] * 3)
    return box


def _write(mesh: trimesh.Trimesh, path: Path) -> Path:
    mesh.export(path)
    return path


def _refused(path: Path, *words: str, units: str | ModelConfig = "mm") -> InputError:
    with pytest.raises(InputError) as info:
        load_surface(path, units)
    message = info.value.one_line()
    assert "\n" not in message
    assert info.value.fix, "every refusal says what to do"
    for word in words:
        assert word in message, message
    return info.value


def test_valid_cube_loads_with_volume_and_size(tmp_path: Path) -> None:
    surface = load_surface(_write(_box(), tmp_path / "cube.stl"))
    assert surface.volume_mm3 == pytest.approx(8000.0, rel=1e-9)
    assert surface.bbox_mm == pytest.approx((20.0, 20.0, 20.0))
    assert surface.vertices.dtype == np.float64 and surface.faces.dtype == np.int32
    assert len(surface.vertices) == 8  # the STL triangle soup was merged
    assert surface.notes == ()
    assert not surface.vertices.flags.writeable
    report = surface.as_report()
    assert report["volume_mm3"] == pytest.approx(8000.0)
    assert report["bbox_mm"] == pytest.approx([20.0, 20.0, 20.0])
    assert report["repairs"] == []


@pytest.mark.parametrize(("units", "scale"), [("cm", 10.0), ("in", 25.4), ("mm", 1.0)])
def test_units_scale_to_millimetres(tmp_path: Path, units: str, scale: float) -> None:
    path = _write(_box(2.0), tmp_path / "small.obj")
    surface = load_surface(path, units)
    assert surface.bbox_mm == pytest.approx((2.0 * scale,) * 3)
    assert surface.volume_mm3 == pytest.approx(8.0 * scale**3)


def test_ply_and_model_config(tmp_path: Path) -> None:
    path = _write(_box(), tmp_path / "cube.ply")
    surface = load_surface(path, ModelConfig(units="mm", max_size_mm=50.0, min_size_mm=5.0))
    assert surface.volume_mm3 == pytest.approx(8000.0)


def test_missing_file(tmp_path: Path) -> None:
    _refused(tmp_path / "nope.stl", "does not exist")


def test_unknown_units(tmp_path: Path) -> None:
    _refused(_write(_box(), tmp_path / "cube.stl"), "units", units="furlong")


def test_unsupported_suffix(tmp_path: Path) -> None:
    path = tmp_path / "model.step"
    path.write_text("ISO-10303-21;")
    _refused(path, "not a surface mesh format")


def test_text_file_named_stl(tmp_path: Path) -> None:
    path = tmp_path / "notes.stl"
    path.write_text("these are my notes, not a mesh\n" * 5)
    _refused(path, "not an STL file")


def test_empty_file(tmp_path: Path) -> None:
    path = tmp_path / "empty.stl"
    path.write_bytes(b"")
    _refused(path, "empty")


def test_mesh_without_triangles(tmp_path: Path) -> None:
    path = tmp_path / "points.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    _refused(path, "no triangles")


def test_open_box_is_refused_with_edge_count(tmp_path: Path) -> None:
    box = _box()
    top = box.face_normals[:, 2] > 0.5
    box.update_faces(~top)
    error = _refused(_write(box, tmp_path / "open.stl"), "not watertight", "4 open edges")
    assert "hole" in error.problem
    assert isinstance(error, SurfaceRefused) and error.reason is SurfaceReason.OPEN


def test_cubes_sharing_an_edge_are_refused_as_non_manifold(tmp_path: Path) -> None:
    low = _box(10.0)
    high = low.copy()
    high.apply_translation([10.0, 10.0, 0.0])  # one vertical edge shared by 4 faces
    both = low + high
    error = _refused(_write(both, tmp_path / "touching.stl"), "1 non-manifold edges")
    assert isinstance(error, SurfaceRefused) and error.reason is SurfaceReason.NON_MANIFOLD


def test_a_file_problem_carries_no_surface_reason(tmp_path: Path) -> None:
    error = _refused(tmp_path / "nope.stl", "does not exist")
    assert not isinstance(error, SurfaceRefused)


def test_every_surface_reason_says_what_it_means() -> None:
    assert all(reason.message for reason in SurfaceReason)


def test_tiny_crack_is_filled_with_note(tmp_path: Path) -> None:
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=20.0)
    sphere.update_faces(np.arange(len(sphere.faces)) != 7)  # one small triangular hole
    surface = load_surface(_write(sphere, tmp_path / "cracked.stl"))
    assert any("filled 1 small holes" in note for note in surface.notes)
    assert surface.volume_mm3 == pytest.approx(trimesh.creation.icosphere(5, 20.0).volume)


def test_inverted_box_is_flipped_with_note(tmp_path: Path) -> None:
    box = _box()
    box.invert()
    surface = load_surface(_write(box, tmp_path / "inverted.stl"))
    assert surface.volume_mm3 == pytest.approx(8000.0)
    assert any("inwards" in note for note in surface.notes)


def test_repeated_faces_are_dropped(tmp_path: Path) -> None:
    box = _box()
    faces = np.vstack([box.faces, box.faces[:2], np.roll(box.faces[2:3], 1, axis=1)])
    path = tmp_path / "repeats.obj"
    _write(trimesh.Trimesh(box.vertices, faces, process=False), path)
    surface = load_surface(path)
    assert len(surface.faces) == 12
    assert any("3 duplicate" in note for note in surface.notes)


def test_mixed_winding_is_made_consistent(tmp_path: Path) -> None:
    box = _box()
    faces = box.faces.copy()
    faces[:3] = faces[:3, ::-1]
    path = tmp_path / "mixed.obj"
    _write(trimesh.Trimesh(box.vertices, faces, process=False), path)
    surface = load_surface(path)
    assert surface.volume_mm3 == pytest.approx(8000.0)
    assert any("consistent winding" in note for note in surface.notes)


def test_flat_mesh_has_zero_volume(tmp_path: Path) -> None:
    # A closed but flat surface: a square, both sides (split along different diagonals).
    v = np.array([[0, 0, 0], [20, 0, 0], [20, 20, 0], [0, 20, 0]], dtype=float)
    f = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]])
    path = tmp_path / "flat.obj"
    _write(trimesh.Trimesh(v, f, process=False), path)
    error = _refused(path, "no volume")
    assert isinstance(error, SurfaceRefused) and error.reason is SurfaceReason.FLAT


def test_ten_km_cube_suggests_units(tmp_path: Path) -> None:
    error = _refused(_write(_box(1e7), tmp_path / "huge.stl"), "larger than")
    assert "--units" in error.fix


def test_tiny_model_suggests_units(tmp_path: Path) -> None:
    error = _refused(_write(_box(0.2), tmp_path / "tiny.stl"), "smaller than")
    assert "--units" in error.fix


def _tet_cube() -> TetMesh:
    """A 10 mm cube split into 6 positive tets around its main diagonal."""
    corners = np.array([[(c >> 2) & 1, (c >> 1) & 1, c & 1] for c in range(8)], float) * 10.0
    tets = np.array(
        [[0, 4, 6, 7], [0, 4, 5, 7], [0, 2, 6, 7], [0, 2, 3, 7], [0, 1, 5, 7], [0, 1, 3, 7]]
    )
    vol = tet_volumes(corners, tets)
    tets[vol < 0] = tets[vol < 0][:, [0, 1, 3, 2]]
    return TetMesh(vertices=corners, tets=tets)


@pytest.mark.parametrize("suffix", [".vtu", ".msh", ".vtk"])
def test_tet_mesh_round_trip(tmp_path: Path, suffix: str) -> None:
    mesh = _tet_cube()
    path = write_tet_mesh(mesh, tmp_path / f"cube{suffix}")
    back = load_tet_mesh(path)
    assert back.vertices.shape == mesh.vertices.shape
    np.testing.assert_allclose(back.vertices, mesh.vertices)
    np.testing.assert_array_equal(back.tets, mesh.tets)
    assert np.all(tet_volumes(back.vertices, back.tets) > 0)
    assert tet_volumes(back.vertices, back.tets).sum() == pytest.approx(1000.0)


def test_tet_mesh_is_oriented_compacted_and_scaled(tmp_path: Path) -> None:
    mesh = _tet_cube()
    points = np.vstack([mesh.vertices, [[50.0, 50.0, 50.0]]]) / 10.0  # unused point, in cm
    tets = np.asarray(mesh.tets)[:, [0, 1, 3, 2]]  # all negative
    path = tmp_path / "raw.vtu"
    meshio.write(path, meshio.Mesh(points, [("tetra", tets)]))
    back = load_tet_mesh(path, "cm")
    assert len(back.vertices) == 8
    assert np.all(tet_volumes(back.vertices, back.tets) > 0)
    assert tet_volumes(back.vertices, back.tets).sum() == pytest.approx(1000.0)


def test_vtu_without_tetra_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "surface.vtu"
    box = _box()
    meshio.write(path, meshio.Mesh(box.vertices, [("triangle", box.faces)]))
    with pytest.raises(InputError, match="no tetrahedra"):
        load_tet_mesh(path)


def test_unreadable_tet_mesh(tmp_path: Path) -> None:
    path = tmp_path / "broken.vtu"
    path.write_text("<VTKFile> not really </VTKFile>")
    with pytest.raises(InputError, match="not a readable tet mesh"):
        load_tet_mesh(path)
    with pytest.raises(InputError, match="does not exist"):
        load_tet_mesh(tmp_path / "missing.msh")


def test_a_model_file_too_large_is_refused_before_reading(tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    from slicer import mesh_io

    path = tmp_path / "big.stl"
    path.write_bytes(b"\0" * 2048)
    monkeypatch.setattr(mesh_io, "MAX_MODEL_BYTES", 1024)
    with pytest.raises(InputError, match="larger than"):
        mesh_io.load_surface(path)
