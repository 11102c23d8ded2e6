from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from core.errors import InputError
from core.stages import Field, Layers, TetMesh
from slicer.config import SlicingConfig
from slicer.field import compute_field
from slicer.layers import (
    extract_layers,
    field_stage,
    iso_surfaces,
    layer_gap,
    layer_spacing,
    slab_bounds,
)
from slicer.operators import build_operators
from tests.slicer.conftest import box_mesh, ring_mesh


def _components(faces: np.ndarray) -> int:
    n = int(faces.max()) + 1
    e = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    return connected_components(sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])),
                                              shape=(n, n)), directed=False)[0]


def _face_normals(layers: Layers) -> np.ndarray:
    p = layers.vertices[layers.faces]
    return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])


def test_spacing_rounds_to_whole_layers() -> None:
    g = np.array([0.0, 10.0])
    s = layer_spacing(g, delta=0.3, layer_height_mm=0.6)
    assert len(s.iso) == 33  # round(10 / 0.3)
    assert s.delta_used == pytest.approx(10 / 33)
    np.testing.assert_allclose(s.iso, (np.arange(33) + 0.5) * 10 / 33)
    assert s.mean_height_mm == pytest.approx(0.6 * (10 / 33) / 0.3)


def test_critical_values_become_slab_boundaries() -> None:
    """A cavity floor at g = 4.4 and a ceiling at 7.0 on a 0..10 field with delta 1: whole
    slabs in [0, 4.4], [4.4, 7], [7, 10]; anchors at the ends or closer than delta / 2 to
    another are dropped."""
    g = np.array([0.0, 10.0])
    s = layer_spacing(g, delta=1.0, layer_height_mm=1.0, anchors=np.array([0.0, 4.4, 4.6, 7.0,
                                                                           9.8]))
    np.testing.assert_allclose(s.anchors, [4.4, 7.0])
    for a in (4.4, 7.0):
        assert np.min(np.abs(s.bounds - a)) < 1e-12
    np.testing.assert_allclose(s.iso, 0.5 * (s.bounds[1:] + s.bounds[:-1]))
    thickness = np.diff(s.bounds)
    np.testing.assert_allclose(thickness, [1.1] * 4 + [2.6 / 3] * 3 + [1.0] * 3)
    assert s.delta_used == pytest.approx(1.0)
    # the middles rebuild their slabs exactly
    np.testing.assert_allclose(slab_bounds(s.iso, 0.0, 10.0), s.bounds, atol=1e-12)


def test_linear_field_closed_form(box: TetMesh) -> None:
    ops = build_operators(box)
    a = np.array([0.2, 0.3, 1.0])
    g = box.vertices @ a
    iso = np.array([2.0, 4.5, 7.25])
    layers = iso_surfaces(ops, Field(g=g, iso=iso))
    assert layers.layer_count == 3
    for k, c in enumerate(iso):
        lay = layers.layer(k)
        np.testing.assert_allclose(lay.vertices @ a, c, atol=1e-12)
        np.testing.assert_allclose(lay.direction, [a / np.linalg.norm(a)] * len(lay.vertices),
                                   atol=1e-12)
        # Each layer is one planar polygon cut from a box: a disc (V - E + F = 1), welded.
        edges = np.sort(lay.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        n_edges = len(np.unique(edges, axis=0))
        assert len(lay.vertices) - n_edges + len(lay.faces) == 1
        # The polygon's area matches the plane-box intersection (integrated numerically).
        p = lay.vertices[lay.faces]
        area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()
        xy = (np.arange(400) + 0.5) / 400 * 8.0
        xx, yy = np.meshgrid(xy, xy)
        z = (c - a[0] * xx - a[1] * yy) / a[2]
        inside = ((z >= 0) & (z <= 8)).mean() * 64.0
        assert area == pytest.approx(inside * np.linalg.norm(a) / a[2], rel=1e-2)
    # Heights: the local spacing of these hand-made iso-values (not slab middles: the gaps
    # to the neighbours' midpoints, 2.5, 2.625, 2.75) over |grad g|.
    for k, t in enumerate((2.5, 2.625, 2.75)):
        np.testing.assert_allclose(layers.layer(k).height, t / np.linalg.norm(a))
    # Faces point along increasing g.
    assert np.all(_face_normals(layers) @ a > 0)


def test_planar_box_layers_flat_at_target(box: TetMesh) -> None:
    res = compute_field(box, SlicingConfig(planar=True, layer_height_mm=0.5))
    field, spacing = field_stage(res, 0.5)
    assert len(field.iso) == 16 and spacing.mean_height_mm == pytest.approx(0.5)
    layers = iso_surfaces(res.operators, field)
    assert layers.layer_count == 16
    for k in range(16):
        z = layers.layer(k).vertices[:, 2]
        assert np.ptp(z) < 1e-12
        assert z[0] == pytest.approx((k + 0.5) * 0.5)
    np.testing.assert_allclose(layers.vertex_height, 0.5, rtol=1e-12)
    np.testing.assert_allclose(layers.vertex_direction, [[0, 0, 1]] * len(layers.vertices),
                               atol=1e-12)


def test_critical_regions_each_on_one_layer(ring: TetMesh) -> None:
    res = compute_field(ring, SlicingConfig(critical=("bottom", "top"), layer_height_mm=0.8))
    field, _ = field_stage(res, 0.8)
    assert len(res.regions.regions) == 2
    for region in res.regions.regions:
        slot = np.searchsorted(field.iso, res.g[region.vertices])
        assert len(np.unique(slot)) == 1
    layers = iso_surfaces(res.operators, field)
    # No layer passes through a region: a region's vertices are never layer vertices.
    for region in res.regions.regions:
        pts = res.operators.vertices[region.vertices]
        d = np.linalg.norm(layers.vertices[:, None, :] - pts[None, :20, :], axis=2)
        assert d.min() > 1e-6


def test_measured_gap_matches_height_on_curved_layers(ring: TetMesh) -> None:
    res = compute_field(ring, SlicingConfig(critical=("top:45",), layer_height_mm=0.8))
    field, _ = field_stage(res, 0.8)
    layers = iso_surfaces(res.operators, field)
    assert layers.layer_count >= 10
    rel = []
    for k in range(layers.layer_count - 1):
        measured, reported = layer_gap(layers, k)
        rel.append(np.abs(measured - reported) / reported)
    assert float(np.median(np.concatenate(rel))) < 0.10
    # Orientation: faces point along the vertex growth directions.
    n = _face_normals(layers)
    d = layers.vertex_direction[layers.faces].mean(axis=1)
    assert np.mean(np.einsum("ij,ij->i", n, d) > 0) == 1.0


def test_layer_with_two_components_keeps_both() -> None:
    a = box_mesh(n=(2, 2, 3), size=(2, 2, 3))
    verts = np.vstack([a.vertices, a.vertices + np.array([5.0, 0.0, 0.0])])
    tets = np.vstack([a.tets, a.tets + len(a.vertices)])
    mesh = TetMesh(verts, tets)
    res = compute_field(mesh, SlicingConfig(planar=True, layer_height_mm=1.0))
    layers = iso_surfaces(res.operators, field_stage(res, 1.0)[0])
    assert layers.layer_count == 3
    for k in range(3):
        assert _components(layers.layer(k).faces) == 2


def test_curved_ring_layers_are_welded_consistent_manifolds() -> None:
    mesh = ring_mesh(nt=24, nz=6)
    res = compute_field(mesh, SlicingConfig(critical=("top:45",), layer_height_mm=1.0))
    layers = iso_surfaces(res.operators, field_stage(res, 1.0)[0])
    assert layers.layer_count >= 8
    for k in range(layers.layer_count):
        lay = layers.layer(k)
        directed = lay.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
        # Consistent orientation: no directed edge twice; welded manifold: <= 2 faces per edge.
        assert len(np.unique(directed, axis=0)) == len(directed)
        _, count = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
        assert count.max() == 2
    # The top layer follows the wavy rim all the way round: one annulus (V - E + F = 0).
    top = layers.layer(layers.layer_count - 1)
    assert _components(top.faces) == 1
    edges = np.unique(np.sort(top.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0)
    assert len(top.vertices) - len(edges) + len(top.faces) == 0


def test_collapsed_triangles_leave_no_vertex_behind() -> None:
    # two tets; the level passes 1e-4 above the apex of the first, so its three crossings
    # snap onto that apex and its triangle collapses; the second tet's crossings stay
    x = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [5, 0, 0], [6, 0, 0],
                  [5, 1, 0], [5, 0, 1]])
    tets = np.array([[0, 1, 2, 3], [4, 5, 6, 7]], dtype=np.int32)
    g = np.array([0.0, 1, 1, 1, 0, 1, 1, 1])
    layers = iso_surfaces(TetMesh(x, tets), Field(g, np.array([1e-4, 0.5])))
    low = layers.layer(0)
    assert len(low.faces) == 0 and len(low.vertices) == 0
    assert np.all(np.isfinite(layers.vertex_height))
    assert np.all(np.isfinite(layers.vertex_direction))
    assert len(np.unique(layers.faces)) == len(layers.vertices)


def test_extract_from_mesh_and_mismatch(box: TetMesh) -> None:
    g = box.vertices[:, 2].copy()
    out = extract_layers(box, Field(g=g, iso=np.array([1.0, 3.0])))
    assert out.layers.layer_count == 2 and out.critical_report == []
    assert out.spacing.delta_used == 2.0
    with pytest.raises(InputError):
        iso_surfaces(box, Field(g=g[:-1], iso=np.array([1.0])))


def test_stage_entry_point_reports_checks(ring: TetMesh) -> None:
    cfg = SlicingConfig(critical=("bottom", "top"), layer_height_mm=0.8)
    res = compute_field(ring, cfg)
    out = extract_layers(ring, res, cfg)
    assert out.layers.layer_count == len(out.field.iso) == len(out.spacing.iso)
    np.testing.assert_array_equal(out.field.g, res.g)
    assert [r["kind"] for r in out.critical_report] == ["start", "end"]
    assert all(r["on_one_layer"] for r in out.critical_report)
    assert all(r["on_slab_boundary"] for r in out.critical_report)
    assert out.critical_report[0]["slot"] == 0
    assert out.critical_report[1]["slot"] == len(out.field.iso)
    assert out.height_check["pairs"] >= 5
    assert out.height_check["median_rel_error"] < 0.10
