"""Only the bodies with an open or non-manifold edge are wrapped; the others kept face for face."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from slicer.body_wrap import troubled_faces, wrap_troubled


def _cube(size: float, at: tuple[float, float, float]) -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=(size, size, size))
    box.apply_translation(at)
    return box


def _two_touching_and_one_alone() -> trimesh.Trimesh:
    """Cubes of 10 mm: two sharing a vertical edge, a third 30 mm away (closed, manifold)."""
    both = _cube(10.0, (0.0, 0.0, 0.0)) + _cube(10.0, (10.0, 10.0, 0.0))
    both = both + _cube(10.0, (40.0, 0.0, 0.0))
    both.merge_vertices()
    return both


def test_only_the_touching_cubes_are_troubled() -> None:
    mesh = _two_touching_and_one_alone()
    bad, bodies, troubled = troubled_faces(np.asarray(mesh.faces), len(mesh.vertices))
    assert (bodies, troubled) == (2, 1)  # the touching pair is one vertex-connected body
    assert np.count_nonzero(bad) == 24
    centre_x = mesh.vertices[mesh.faces].mean(axis=1)[:, 0]
    assert not bad[centre_x > 30.0].any()


def test_a_closed_surface_has_no_troubled_body() -> None:
    cube = _cube(10.0, (0.0, 0.0, 0.0))
    bad, bodies, troubled = troubled_faces(np.asarray(cube.faces), len(cube.vertices))
    assert (bodies, troubled) == (1, 0) and not bad.any()


def test_the_lone_cube_is_kept_and_the_pair_wrapped() -> None:
    mesh = _two_touching_and_one_alone()
    v, f, summary = wrap_troubled(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    out = trimesh.Trimesh(v, f, process=False)
    assert out.is_watertight and out.is_winding_consistent and out.body_count == 3
    assert (summary.bodies, summary.bodies_wrapped) == (2, 1)
    assert summary.faces_before == 36 and summary.faces_after == len(f)
    alone = f[v[f].mean(axis=1)[:, 0] > 30.0]
    assert len(alone) == 12  # face for face
    assert np.allclose(np.sort(v[np.unique(alone)], axis=0),
                       np.sort(_cube(10.0, (40.0, 0.0, 0.0)).vertices, axis=0))
    assert summary.volume_before == pytest.approx(3000.0)
    assert out.volume == pytest.approx(3000.0, rel=0.03)
