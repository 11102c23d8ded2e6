from __future__ import annotations

import numpy as np

from core.stages import TetMesh
from slicer.config import CriticalSelector
from slicer.critical import select_critical_regions
from slicer.operators import build_operators
from tests.slicer.conftest import box_mesh, grid_tets


def _sel(*texts: str) -> list[CriticalSelector]:
    return [CriticalSelector.parse(t) for t in texts]


def test_box_bottom_and_top(box: TetMesh) -> None:
    ops = build_operators(box)
    sel = select_critical_regions(ops, _sel("bottom", "top:30"))
    assert len(sel.regions) == 2 and sel.notes == ()
    bottom, top = sel.regions
    assert len(bottom.faces) == len(top.faces) == 32  # 4x4 cells, 2 triangles each
    np.testing.assert_allclose(bottom.normals, [[0, 0, -1]] * 32, atol=1e-12)
    # Bottom is a start surface: growth = -normal = +z; top is an end surface: growth = +normal.
    assert bottom.sign == -1.0 and top.sign == 1.0
    np.testing.assert_allclose(bottom.growth, [[0, 0, 1]] * 32, atol=1e-12)
    np.testing.assert_allclose(top.growth, [[0, 0, 1]] * 32, atol=1e-12)
    np.testing.assert_allclose(ops.vertices[bottom.vertices, 2], 0.0)
    np.testing.assert_allclose(ops.vertices[top.vertices, 2], 8.0)
    assert len(bottom.vertices) == 25
    assert bottom.area == 64.0


def _two_boxes() -> TetMesh:
    """Two 2 mm boxes, the second 5 mm along x and 1 mm higher: tops at z = 2 and 3."""
    a = box_mesh(n=(2, 2, 2), size=(2, 2, 2))
    b = box_mesh(n=(2, 2, 2), size=(2, 2, 2))
    verts = np.vstack([a.vertices, b.vertices + np.array([5.0, 0.0, 1.0])])
    return TetMesh(verts, np.vstack([a.tets, b.tets + len(a.vertices)]))


def test_one_selector_two_patches() -> None:
    ops = build_operators(_two_boxes())
    sel = select_critical_regions(ops, _sel("top"))
    assert len(sel.regions) == 2
    tops = sorted(float(ops.vertices[r.vertices, 2].mean()) for r in sel.regions)
    assert tops == [2.0, 3.0]
    # Patches are disjoint and cover all up-facing faces.
    faces = np.concatenate([r.faces for r in sel.regions])
    assert len(np.unique(faces)) == len(faces) == int((ops.boundary.normal[:, 2] > 0.9).sum())


def test_tiny_patches_dropped_with_note(box: TetMesh) -> None:
    ops = build_operators(box)
    sel = select_critical_regions(ops, _sel("top", "bottom"), min_faces=40)
    assert sel.regions == ()
    assert len(sel.notes) == 2 and "fewer than 40" in sel.notes[0]


def test_no_match_noted_and_faces_not_reused(box: TetMesh) -> None:
    ops = build_operators(box)
    sel = select_critical_regions(ops, _sel("normal:1,1,1:10", "top", "top:60"))
    assert len(sel.regions) == 1
    assert any("matched no boundary face" in n for n in sel.notes)


def test_position_condition_keeps_only_matching_patches() -> None:
    ops = build_operators(_two_boxes())
    sel = select_critical_regions(ops, _sel("top@z>2.5"))
    assert len(sel.regions) == 1
    assert float(ops.vertices[sel.regions[0].vertices, 2].mean()) == 3.0
    assert any("left out 1 patch" in n for n in sel.notes)
    # the faces it left out are still free for the next selector
    both = select_critical_regions(ops, _sel("top@z>2.5@x>4", "top"))
    assert sorted(float(ops.vertices[r.vertices, 2].mean()) for r in both.regions) == [2.0, 3.0]
    none = select_critical_regions(ops, _sel("top@z>10"))
    assert none.regions == () and any("kept no patch" in n for n in none.notes)


def test_end_keeps_only_the_patch_at_the_parts_lowest_point() -> None:
    # An L-shaped step: two downward faces, the base at z = 0 and the overhang's underside at
    # z = 4; bottom@end takes the base only, plain bottom both.
    coords, tets = grid_tets(4, 2, 4)
    keep = ~((coords[tets][:, :, 0].mean(axis=1) > 2) & (coords[tets][:, :, 2].mean(axis=1) < 2))
    used = np.unique(tets[keep])
    remap = -np.ones(len(coords), dtype=np.int64)
    remap[used] = np.arange(len(used))
    mesh = TetMesh(coords[used] * 2.0, remap[tets[keep]])
    ops = build_operators(mesh)
    plain = select_critical_regions(ops, _sel("bottom:10"))
    assert len(plain.regions) == 2
    end = select_critical_regions(ops, _sel("bottom:10@end"))
    assert len(end.regions) == 1
    assert float(ops.vertices[end.regions[0].vertices][:, 2].max()) == 0.0
    assert any("away from the part's end" in n for n in end.notes)
