"""Splitting a closed surface where its parts touch: each part a closed manifold shell, the
faces around a crowded edge paired by the wedge of solid they bound."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from slicer.shell_split import bisect_crowded, non_manifold_edges, separate_shells, split_pinches


def _box(size: float = 10.0) -> trimesh.Trimesh:
    return trimesh.creation.box(extents=(size, size, size))


def test_boxes_stacked_face_to_face_become_two_shells() -> None:
    """The face between them is there twice, wound both ways: both lie in one half-plane
    around each of its edges (a tie the pairing must break the right way)."""
    low, high = _box(), _box()
    high.apply_translation([0.0, 0.0, 10.0])
    both = low + high
    both.merge_vertices()
    assert non_manifold_edges(np.asarray(both.faces)) == 4
    v, f, split = separate_shells(np.asarray(both.vertices), np.asarray(both.faces), 0.0)
    apart = trimesh.Trimesh(v, f, process=False)
    assert split == 4 and non_manifold_edges(f) == 0
    assert apart.is_watertight and apart.is_winding_consistent and apart.body_count == 2
    assert sorted(b.volume for b in apart.split(only_watertight=True)) == pytest.approx(
        [1000.0, 1000.0])


def test_boxes_crossing_through_a_shared_edge_keep_their_own_faces() -> None:
    """Box B turned 100 deg about box A's corner edge (shared, 4 faces): the wedges cross;
    pairing by nesting would join A's faces to B's, a surface through itself."""
    a = _box()
    a.apply_translation([-5.0, -5.0, 0.0])
    b = a.copy()
    b.apply_transform(trimesh.transformations.rotation_matrix(np.radians(280.0), [0, 0, 1]))
    both = a + b
    both.merge_vertices()
    v, f, split = separate_shells(np.asarray(both.vertices), np.asarray(both.faces), 0.0)
    apart = trimesh.Trimesh(v, f, process=False)
    assert split == 2 and apart.body_count == 2
    shells = apart.split(only_watertight=True)
    assert [s.volume for s in shells] == pytest.approx([1000.0, 1000.0])
    owners = [[np.allclose(np.sort(s.vertices, axis=0), np.sort(box.vertices, axis=0))
               for box in (a, b)] for s in shells]
    assert sorted(owners) == [[False, True], [True, False]]  # one shell is A, the other B


def test_boxes_touching_along_an_edge_become_two_shells() -> None:
    low = trimesh.creation.box(extents=(10.0, 10.0, 10.0))
    high = low.copy()
    high.apply_translation([10.0, 10.0, 0.0])  # shares the vertical edge x = y = 5
    both = low + high
    both.merge_vertices()
    assert non_manifold_edges(np.asarray(both.faces)) == 1
    v, f, split = split_pinches(np.asarray(both.vertices), np.asarray(both.faces), 1e-4)
    assert split == 2 and len(v) == len(both.vertices) + 2
    apart = trimesh.Trimesh(v, f, process=False)
    assert apart.is_watertight and apart.is_winding_consistent
    assert non_manifold_edges(f) == 0 and apart.body_count == 2
    assert apart.volume == pytest.approx(2000.0, rel=1e-4)


def test_bisecting_a_crowded_edge_keeps_the_surface_closed() -> None:
    low = trimesh.creation.box(extents=(10.0, 10.0, 10.0))
    high = low.copy()
    high.apply_translation([10.0, 10.0, 0.0])
    both = low + high
    both.merge_vertices()
    v, f = bisect_crowded(np.asarray(both.vertices), np.asarray(both.faces))
    assert len(v) == len(both.vertices) + 1 and len(f) == len(both.faces) + 4
    assert non_manifold_edges(f) == 2  # the two halves of the shared edge
    v, f, split = split_pinches(v, f, 1e-4)
    apart = trimesh.Trimesh(v, f, process=False)
    assert split == 3 and apart.is_watertight and apart.body_count == 2
    assert apart.volume == pytest.approx(2000.0, rel=1e-4)


def test_a_face_with_two_crowded_edges_gets_both_split_in_two_rounds() -> None:
    """Cube A with cubes touching two of its top edges: a face of A holds both crowded
    edges; each round splits one of them (the lowest), so neither stays blocked."""
    def cube(at: tuple[float, float, float]) -> trimesh.Trimesh:
        box = trimesh.creation.box(extents=(10.0, 10.0, 10.0))
        box.apply_translation(at)
        return box

    both = cube((0.0, 0.0, 0.0)) + cube((10.0, 0.0, 10.0)) + cube((0.0, 10.0, 10.0))
    both.merge_vertices()
    v, f = np.asarray(both.vertices, dtype=np.float64), np.asarray(both.faces)
    uses = {}
    for a, b in np.sort(f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1):
        uses[(a, b)] = uses.get((a, b), 0) + 1
    face = next(t for t in f if sum(uses[tuple(sorted((t[k], t[(k + 1) % 3])))] > 2
                                    for k in range(3)) == 2)
    crowded = [tuple(sorted((face[k], face[(k + 1) % 3]))) for k in range(3)
               if uses[tuple(sorted((face[k], face[(k + 1) % 3])))] > 2]
    mids = [0.5 * (v[a] + v[b]) for a, b in crowded]

    def split_at(points: np.ndarray) -> list[bool]:
        return [bool(np.any(np.linalg.norm(points - m, axis=1) < 1e-9)) for m in mids]

    v1, f1 = bisect_crowded(v, f)
    assert sorted(split_at(v1)) == [False, True]  # one per face and round
    v2, _ = bisect_crowded(v1, f1)
    assert split_at(v2) == [True, True]
