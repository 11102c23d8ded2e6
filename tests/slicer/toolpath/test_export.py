"""toolpath.npz and the per-layer text files round-trip."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from core.stages import Toolpath
from slicer.toolpath.export import (
    HEADER,
    export_layers_txt,
    read_layer_txt,
    save_toolpath,
)


def _toolpath() -> Toolpath:
    rng = np.random.default_rng(1)
    n = 40
    normal = rng.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    layer = np.repeat([0, 1], 20)
    extrude = np.ones(n, bool)
    extrude[8:11] = False
    path = np.concatenate([np.zeros(8), np.ones(3), np.full(9, 2), np.full(20, 3)])
    return Toolpath(
        position=rng.uniform(-10, 10, (n, 3)), normal=normal, layer=layer,
        path=path.astype(np.int32), height=rng.uniform(0.4, 0.8, n),
        width=rng.uniform(1, 3, n), speed=rng.uniform(1, 10, n), extrude=extrude,
        pattern=(layer % 2).astype(np.int8),
    )


def test_npz_round_trip(tmp_path: Path) -> None:
    tp = _toolpath()
    path = save_toolpath(tp, tmp_path)
    assert path.name == "toolpath.npz"
    back = Toolpath.load(tmp_path)
    for name, arr in tp.arrays().items():
        assert np.array_equal(arr, back.arrays()[name]), name
        assert arr.dtype == back.arrays()[name].dtype


def test_layer_text_round_trip(tmp_path: Path) -> None:
    tp = _toolpath()
    files = export_layers_txt(tp, tmp_path / "layers_txt")
    assert [f.name for f in files] == ["layer_0000.txt", "layer_0001.txt"]
    first = files[0].read_text().splitlines()[0]
    assert first.startswith("#") and HEADER in first
    for layer, file in enumerate(files):
        back = read_layer_txt(file)
        sel = (tp.layer == layer) & tp.extrude
        assert np.allclose(back.position, tp.position[sel], atol=1e-6)
        assert np.allclose(back.normal, tp.normal[sel], atol=1e-6)
        assert np.allclose(back.width, tp.width[sel], atol=1e-6)
        assert np.allclose(back.height, tp.height[sel], atol=1e-6)
        assert np.allclose(back.speed, tp.speed[sel], atol=1e-6)
        assert np.array_equal(back.path, tp.path[sel])


def test_read_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError):
        read_layer_txt(tmp_path / "none.txt")
    bad = tmp_path / "bad.txt"
    bad.write_text("# x\n1 2 3\n")
    with pytest.raises(InputError, match="9"):
        read_layer_txt(bad)
