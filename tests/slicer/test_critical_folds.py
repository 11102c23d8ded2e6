"""A fold forced by two critical regions: a start and an end surface that touch (a sheet whose
top and bottom faces meet at a sharp edge) share one field value, so the layers would grow
out of one and end on the other and fold back between them. The slicer drops the smaller one
before the field is built and says which and why."""

from __future__ import annotations

import functools

import numpy as np
import pytest

import slicer.field as field_module
from core.stages import TetMesh
from slicer.config import CriticalSelector, SlicingConfig
from slicer.critical import select_critical_regions
from slicer.field import compute_field
from slicer.operators import build_operators
from tests.slicer.conftest import box_mesh


def _blade(L: float = 12.0, top: float = 4.0, bottom: float = 2.0, width: float = 8.0,
           n: int = 8, ny: int = 4) -> TetMesh:
    """A blade along y: its cross-section a kite with tips at x = +-L, the top faces rising
    ``top`` mm to a ridge at x = 0 (18 deg), the bottom faces ``bottom`` mm below (9.5 deg):
    both within the 45 deg cones of 'top' and 'bottom', meeting at the sharp edges x = +-L.
    The unit square mapped bilinearly onto the kite, two triangles per cell, each triangle
    extruded along y into a prism of three tets (split by vertex order, so faces conform)."""
    u, v = (a.ravel() for a in np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1),
                                           indexing="ij"))
    corners = np.array([[-L, 0.0], [0.0, -bottom], [L, 0.0], [0.0, top]])
    w = np.stack([(1 - u) * (1 - v), u * (1 - v), u * v, (1 - u) * v], axis=1)
    xz = w @ corners
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    tri = np.sort(np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]), axis=1)
    m = len(xz)
    ys = np.linspace(0.0, width, ny + 1)
    P = np.concatenate([np.column_stack([xz[:, 0], np.full(m, y), xz[:, 1]]) for y in ys])
    tets = []
    for j in range(ny):  # a loop over the few slabs along y
        lo, hi = tri + j * m, tri + (j + 1) * m
        tets += [np.column_stack([lo[:, 0], lo[:, 1], lo[:, 2], hi[:, 2]]),
                 np.column_stack([lo[:, 0], lo[:, 1], hi[:, 1], hi[:, 2]]),
                 np.column_stack([lo[:, 0], hi[:, 0], hi[:, 1], hi[:, 2]])]
    return TetMesh(P, np.concatenate(tets).astype(np.int64))


def _sel() -> list[CriticalSelector]:
    return [CriticalSelector.parse("bottom"), CriticalSelector.parse("top")]


def test_touching_start_and_end_regions_keep_the_larger_and_name_the_other() -> None:
    ops = build_operators(_blade())
    both = select_critical_regions(ops, _sel(), folds=False)
    assert sorted(r.sign for r in both.regions) == [-1.0, 1.0]
    start, end = sorted(both.regions, key=lambda r: r.sign)
    assert np.intersect1d(start.vertices, end.vertices).size > 0  # they touch: one value
    kept = select_critical_regions(ops, _sel())
    assert [r.selector for r in kept.regions] == ["top"]  # the larger (its faces are longer)
    line = [n for n in kept.notes if "fold" in n]
    assert len(line) == 1 and "'bottom'" in line[0] and "start" in line[0]
    assert "'top'" in line[0] and "\n" not in line[0]


def test_regions_that_do_not_touch_are_all_kept() -> None:
    # a box: its top and bottom are apart (the vertical sides lie between them)
    sel = select_critical_regions(build_operators(box_mesh()), _sel())
    assert sorted(r.selector for r in sel.regions) == ["bottom", "top"]
    assert not [n for n in sel.notes if "fold" in n]


def test_the_field_no_longer_folds_between_them(monkeypatch: pytest.MonkeyPatch) -> None:
    mesh = _blade()
    config = SlicingConfig(critical=("bottom", "top"), layer_height_mm=0.5)

    def downward(result: field_module.FieldResult) -> float:
        """Volume share of tets whose layers grow downward (grad g more than 90 deg off +z)."""
        g = result.gradient
        vol = result.operators.volume
        down = g[:, 2] < 0.0
        return float(vol[down].sum() / vol.sum())

    resolved = compute_field(mesh, config)
    assert downward(resolved) < 0.01
    assert any("fold" in n for n in resolved.notes)
    monkeypatch.setattr(field_module, "select_critical_regions",
                        functools.partial(select_critical_regions, folds=False))
    folded = compute_field(mesh, config)
    assert downward(folded) > 0.1  # what the fixture reproduces without the resolution
