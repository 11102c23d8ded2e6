"""The solid's volume counts overlapping shells once and cuts cavities out."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from slicer.solid_volume import shells, signed_volume, solid_volume


def _boxes(*boxes: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    both = trimesh.util.concatenate(list(boxes))
    return np.asarray(both.vertices), np.asarray(both.faces)


def test_one_shell_is_its_signed_volume() -> None:
    box = trimesh.creation.box((2.0, 3.0, 4.0))
    assert solid_volume(box.vertices, box.faces) == pytest.approx(24.0)


def test_overlapping_shells_count_once() -> None:
    """Two 2 mm cubes overlapping by half: 12 mm^3, not the 16 their shells sum to (a scan's
    eyes sunk into its head)."""
    a = trimesh.creation.box((2.0, 2.0, 2.0))
    b = trimesh.creation.box((2.0, 2.0, 2.0))
    b.apply_translation((1.0, 0.0, 0.0))
    v, f = _boxes(a, b)
    assert len(np.unique(shells(f))) == 2
    assert signed_volume(v, f) == pytest.approx(16.0)
    assert solid_volume(v, f) == pytest.approx(12.0, rel=1e-5)


def test_apart_shells_add_and_a_cavity_is_cut_out() -> None:
    a = trimesh.creation.box((2.0, 2.0, 2.0))
    b = trimesh.creation.box((1.0, 1.0, 1.0))
    b.apply_translation((5.0, 0.0, 0.0))
    v, f = _boxes(a, b)
    assert solid_volume(v, f) == pytest.approx(9.0, rel=1e-5)
    outer = trimesh.creation.box((4.0, 4.0, 4.0))
    hole = trimesh.creation.box((2.0, 2.0, 2.0))
    hole.faces = hole.faces[:, ::-1]  # inward: a cavity
    v, f = _boxes(outer, hole)
    assert solid_volume(v, f) == pytest.approx(56.0, rel=1e-5)
