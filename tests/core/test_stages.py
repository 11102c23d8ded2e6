"""Stage values: immutability, validation and the save/load round trip."""

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from core.stages import Field, Layers, TetMesh, Toolpath


def _tetmesh() -> TetMesh:
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    return TetMesh(vertices=vertices, tets=np.array([[0, 1, 2, 3]]))


def _toolpath(n: int = 5) -> Toolpath:
    rng = np.random.default_rng(0)
    return Toolpath(
        position=rng.normal(size=(n, 3)),
        normal=np.tile([0.0, 0.0, 1.0], (n, 1)),
        layer=np.zeros(n, int),
        path=np.zeros(n, int),
        height=np.full(n, 0.6),
        width=np.full(n, 1.2),
        speed=np.full(n, 9.0),
        extrude=np.ones(n, bool),
        pattern=np.zeros(n, int),
    )


def test_stage_arrays_are_read_only() -> None:
    mesh = _tetmesh()
    with pytest.raises(ValueError):
        mesh.vertices[0, 0] = 5.0
    with pytest.raises(AttributeError):
        mesh.vertices = np.zeros((4, 3))  # type: ignore[misc]


def test_stage_does_not_alias_caller_arrays() -> None:
    vertices = np.zeros((4, 3))
    mesh = TetMesh(vertices=vertices, tets=np.array([[0, 1, 2, 3]], dtype=np.int32))
    vertices[0, 0] = 7.0
    assert mesh.vertices[0, 0] == 0.0


def test_roundtrip_all_stages(tmp_path: Path) -> None:
    mesh = _tetmesh()
    mesh.save(tmp_path)
    back = TetMesh.load(tmp_path)
    np.testing.assert_array_equal(back.vertices, mesh.vertices)
    assert back.tets.dtype == np.int32

    field = Field(g=np.arange(4.0), iso=np.array([0.5, 1.5]))
    field.save(tmp_path)
    np.testing.assert_array_equal(Field.load(tmp_path).iso, field.iso)

    layers = Layers(
        vertices=np.eye(3),
        faces=np.array([[0, 1, 2]]),
        face_layer=np.array([0]),
        vertex_height=np.full(3, 0.6),
        vertex_direction=np.tile([0.0, 0.0, 1.0], (3, 1)),
    )
    layers.save(tmp_path)
    loaded = Layers.load(tmp_path)
    assert loaded.layer_count == 1
    assert loaded.layer(0).faces.shape == (1, 3)

    path = _toolpath()
    path.save(tmp_path)
    again = Toolpath.load(tmp_path)
    assert len(again) == 5 and again.pattern.dtype == np.int8 and again.extrude.dtype == bool


def test_inconsistent_stage_is_refused() -> None:
    with pytest.raises(ValueError, match="outside"):
        TetMesh(vertices=np.zeros((3, 3)), tets=np.array([[0, 1, 2, 3]]))
    with pytest.raises(ValueError, match="increase"):
        Field(g=np.zeros(3), iso=np.array([1.0, 0.5]))


def test_missing_or_corrupt_file_is_input_error(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="does not exist"):
        TetMesh.load(tmp_path)
    (tmp_path / "tetmesh.npz").write_text("not a zip")
    with pytest.raises(InputError, match="not a readable"):
        TetMesh.load(tmp_path)
    np.savez(tmp_path / "toolpath.npz", position=np.zeros((2, 3)))
    with pytest.raises(InputError, match="no array 'normal'"):
        Toolpath.load(tmp_path)


def test_save_is_atomic_and_leaves_no_temp_files(tmp_path: Path) -> None:
    _tetmesh().save(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tetmesh.npz"]


def test_stage_files_are_readable_by_the_lab(tmp_path: Path) -> None:
    from core.artifacts import atomic_write_bytes, save_npz

    atomic_write_bytes(tmp_path / "report.json", b"{}")
    save_npz(tmp_path / "a.npz", {"x": np.zeros(3)})
    for name in ("report.json", "a.npz"):
        assert (tmp_path / name).stat().st_mode & 0o777 == 0o644


def test_a_loaded_toolpath_must_be_printable(tmp_path: Path) -> None:
    from tests.fuzz.fixtures import toolpath_arrays

    good = toolpath_arrays()
    np.savez(tmp_path / Toolpath.FILE, **good)
    assert len(Toolpath.load(tmp_path)) == len(good["position"])
    for name, value, needle in (("position", np.nan, "NaN"), ("speed", 0.0, "speed"),
                                ("speed", -5.0, "speed"), ("width", 1e9, "width"),
                                ("extrude", False, "deposits nothing"),
                                ("normal", 0.0, "unit"), ("layer", -1, "negative"),
                                ("position", 1e7, "beyond")):
        arrays = {k: v.copy() for k, v in good.items()}
        arrays[name][:] = value
        np.savez(tmp_path / Toolpath.FILE, **arrays)
        with pytest.raises(InputError, match=needle):
            Toolpath.load(tmp_path)
    np.savez(tmp_path / Toolpath.FILE, **{k: v[:0] for k, v in good.items()})
    with pytest.raises(InputError, match="no waypoint"):
        Toolpath.load(tmp_path)


def test_the_file_schema_follows_the_one_declaration() -> None:
    from core.stages import Pattern, Stage, column

    assert TetMesh.SCHEMA == {"vertices": (2, "f", (3,)), "tets": (2, "iu", (4,))}
    assert TetMesh.DTYPES == {"vertices": np.float64, "tets": np.int32}
    assert Toolpath.SCHEMA["extrude"] == (1, "b", None)
    assert Toolpath.SCHEMA["pattern"] == (1, "iu", None) and Toolpath.DTYPES["pattern"] is np.int8
    assert list(Toolpath.DTYPES) == ["position", "normal", "layer", "path", "height", "width",
                                     "speed", "extrude", "pattern"]

    @dataclass(frozen=True, eq=False)
    class Pair(Stage):
        a: np.ndarray = column(np.float32, 2, 2)
        b: np.ndarray = column(np.uint8)

    assert Pair.SCHEMA == {"a": (3, "f", (2, 2)), "b": (1, "iu", None)}
    assert [int(p) for p in Pattern] == [0, 1] and Pattern.STRIPE.label == "stripe"
