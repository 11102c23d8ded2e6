"""Repeatable slices: the tet mesh made once for an input is read back for the same input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from core.stages import Toolpath
from mesp_cell.cli import main
from slicer import tet_cache
from slicer.config import MeshConfig
from slicer.mesh_io import Surface, load_surface
from slicer.tetrahedralize import tetrahedralize


@pytest.fixture(scope="module")
def cube(tmp_path_factory: pytest.TempPathFactory) -> Surface:
    path = tmp_path_factory.mktemp("cube") / "cube.stl"
    box = trimesh.creation.box(extents=(20.0, 20.0, 20.0))
    box.apply_translation([10.0, 10.0, 10.0])
    box.export(path)
    return load_surface(path)


def test_the_second_mesh_is_the_first(cube: Surface, tmp_path: Path) -> None:
    config = MeshConfig(edge_length_mm=5.0)
    first, s1 = tetrahedralize(cube, config, cache=tmp_path)
    second, s2 = tetrahedralize(cube, config, cache=tmp_path)
    assert not s1.cached and s2.cached
    assert np.array_equal(first.vertices, second.vertices)
    assert np.array_equal(first.tets, second.tets)
    assert s2.tets == s1.tets and s2.volume_mm3 == s1.volume_mm3
    # other settings are another mesh
    _, s3 = tetrahedralize(cube, MeshConfig(edge_length_mm=6.0), cache=tmp_path)
    assert not s3.cached and len(list(tmp_path.glob("*.npz"))) == 2


def test_the_key_follows_input_and_settings(cube: Surface) -> None:
    config = MeshConfig(edge_length_mm=5.0)
    key = tet_cache.cache_key(cube, config, 0.0)
    assert key == tet_cache.cache_key(cube, config, 0.0)
    assert key != tet_cache.cache_key(cube, MeshConfig(edge_length_mm=5.0, epsilon=1e-3), 0.0)
    assert key != tet_cache.cache_key(cube, config, 0.5)
    moved = Surface(cube.vertices + 1e-9, cube.faces, cube.source)
    assert key != tet_cache.cache_key(moved, config, 0.0)


def test_a_broken_entry_is_a_miss(cube: Surface, tmp_path: Path) -> None:
    config = MeshConfig(edge_length_mm=5.0)
    key = tet_cache.cache_key(cube, config, 0.0)
    (tmp_path / f"{key}.npz").write_bytes(b"not a zip")
    assert tet_cache.load(tmp_path, key) is None
    _, stats = tetrahedralize(cube, config, cache=tmp_path)
    assert not stats.cached and tet_cache.load(tmp_path, key) is not None


def test_where_the_cache_lives(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv(tet_cache.CACHE_ENV, "off")
    assert tet_cache.cache_dir() is None
    monkeypatch.setenv(tet_cache.CACHE_ENV, str(tmp_path))
    assert tet_cache.cache_dir() == tmp_path
    monkeypatch.delenv(tet_cache.CACHE_ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert tet_cache.cache_dir() == tmp_path / "mesp" / "tetmesh"


def test_the_same_slice_gives_the_same_toolpath(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(tet_cache.CACHE_ENV, str(tmp_path / "cache"))
    model = tmp_path / "part.stl"
    cyl = trimesh.creation.cylinder(radius=10.0, height=8.0, sections=48)
    cyl.apply_translation([0.0, 0.0, 4.0])
    cyl.export(model)
    paths = []
    for name in ("a", "b"):
        out = tmp_path / name
        assert main(["slice", str(model), "--out", str(out), "--quiet", "--no-baselines",
                     "--edge-length", "2.5", "--layer-height", "1.0"]) == 0
        paths.append(Toolpath.load(out))
    a, b = paths
    assert np.array_equal(a.position, b.position) and np.array_equal(a.normal, b.normal)
    assert np.array_equal(a.speed, b.speed) and np.array_equal(a.path, b.path)
