"""The union of a surface's shells: one closed manifold boundary, overlaps counted once,
cavities cut out."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from slicer.shell_split import non_manifold_edges, open_edges
from slicer.shell_union import union_shells


def _boxes(*centres: tuple[float, float, float], size: float = 10.0) -> trimesh.Trimesh:
    parts = []
    for centre in centres:
        box = trimesh.creation.box(extents=(size, size, size))
        box.apply_translation(centre)
        parts.append(box)
    return trimesh.util.concatenate(parts)


def test_overlapping_boxes_become_one_closed_surface() -> None:
    both = _boxes((0.0, 0.0, 0.0), (5.0, 0.0, 0.0))  # overlap 5 x 10 x 10 mm
    joined = union_shells(np.asarray(both.vertices), np.asarray(both.faces))
    assert joined is not None
    v, f = joined
    mesh = trimesh.Trimesh(v, f, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.body_count == 1
    assert non_manifold_edges(f) == 0 and open_edges(f) == 0
    assert mesh.volume == pytest.approx(1500.0)


def test_a_cavity_is_cut_out() -> None:
    outer = trimesh.creation.box(extents=(10.0, 10.0, 10.0))
    inner = trimesh.creation.box(extents=(4.0, 4.0, 4.0))
    inner.invert()  # wound inward: a void
    joined = union_shells(*(np.vstack([outer.vertices, inner.vertices]),
                            np.vstack([outer.faces, inner.faces + len(outer.vertices)])))
    assert joined is not None
    assert trimesh.Trimesh(*joined, process=False).volume == pytest.approx(1000.0 - 64.0)


def test_a_shell_that_is_no_manifold_gives_none() -> None:
    box = trimesh.creation.box(extents=(10.0, 10.0, 10.0))
    opened = np.asarray(box.faces)[1:]  # one face missing: open
    assert union_shells(np.asarray(box.vertices), opened) is None
