"""Ordering and linking of lines into continuous paths; lifted travel moves."""

from __future__ import annotations

import numpy as np
import pytest

from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.linking import (
    Lifter,
    deposit_mask,
    link_pieces,
    mesh_graph,
    surface_connector,
)
from slicer.toolpath.mapback import barycentric
from slicer.toolpath.ordering import line_levels, order_lines

from .test_build import disc_mesh


def _locate(points: np.ndarray, v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Face and barycentrics of points on a flat mesh (brute force, tiny meshes only)."""
    face = np.zeros(len(points), np.int32)
    bary = np.zeros((len(points), 3))
    for i, p in enumerate(points):
        b = barycentric(np.repeat(p[None], len(f), 0), v, f, np.arange(len(f), dtype=np.int32))
        k = int(np.argmax(b.min(axis=1)))
        face[i], bary[i] = k, b[k]
    return face, bary


def _circles(v: np.ndarray, f: np.ndarray, radii: list[float], n: int = 60) -> SurfaceLines:
    pts, line = [], []
    for i, r in enumerate(radii):
        a = np.linspace(0, 2 * np.pi, n, endpoint=False)
        pts.append(np.column_stack([r * np.cos(a), r * np.sin(a), np.zeros(n)]))
        line.append(np.full(n, i))
    p = np.concatenate(pts)
    face, bary = _locate(p, v, f)
    return SurfaceLines(p, face, bary, np.concatenate(line).astype(np.int32),
                        np.ones(len(radii), bool))


def _segments(v: np.ndarray, f: np.ndarray, ys: list[float], x0: float, x1: float
              ) -> SurfaceLines:
    pts, line = [], []
    for i, y in enumerate(ys):
        x = np.linspace(x0, x1, 20)
        pts.append(np.column_stack([x, np.full(20, y), np.zeros(20)]))
        line.append(np.full(20, i))
    p = np.concatenate(pts)
    face, bary = _locate(p, v, f)
    return SurfaceLines(p, face, bary, np.concatenate(line).astype(np.int32),
                        np.zeros(len(ys), bool))


@pytest.fixture(scope="module")
def disc() -> tuple[np.ndarray, np.ndarray]:
    return disc_mesh(10.0, 1.0)


def test_mesh_graph(disc: tuple[np.ndarray, np.ndarray]) -> None:
    v, f = disc
    mg = mesh_graph(v, f)
    g = mg.graph
    assert (g != g.T).nnz == 0
    assert np.all(np.isin(np.arange(len(v)), f[mg.vertex_face].ravel()))
    assert np.all(f[mg.vertex_face, mg.vertex_corner] == np.arange(len(v)))


def test_connector_length_and_limit(disc: tuple[np.ndarray, np.ndarray]) -> None:
    v, f = disc
    mg = mesh_graph(v, f)
    p = np.array([[-3.0, 0.2, 0.0], [3.0, -0.1, 0.0]])
    face, _ = _locate(p, v, f)
    c = surface_connector(mg, v, f, p[0], int(face[0]), p[1], int(face[1]), 20.0)
    assert c is not None
    chord = float(np.linalg.norm(p[1] - p[0]))
    # along mesh edges: no shorter than the chord, not much longer on a regular mesh
    assert chord <= c.length <= 1.3 * chord
    assert np.allclose(c.points[:, 2], 0.0)
    assert surface_connector(mg, v, f, p[0], int(face[0]), p[1], int(face[1]), 5.0) is None
    lifter = Lifter(v, np.tile([0.0, 0.0, 1.0], (len(v), 1)))
    straight = surface_connector(mg, v, f, p[0], int(face[0]), p[1], int(face[1]), 20.0,
                                 lifter)
    assert straight is not None and straight.length == pytest.approx(chord)
    assert len(straight.points) == 0


def test_contours_link_into_one_path(disc: tuple[np.ndarray, np.ndarray]) -> None:
    v, f = disc
    lines = _circles(v, f, [9.0, 7.5, 6.0, 4.5, 3.0])
    level = line_levels(lines, 10.0 - np.linalg.norm(lines.points[:, :2], axis=1))
    pieces = order_lines(lines, np.array([20.0, 0.0, 0.0]), level, 1.5)
    # outside-in
    assert [p.line for p in pieces] == [0, 1, 2, 3, 4]
    # closed loops are printed all the way round, starting near the nozzle
    assert pieces[0].points[0] == pieces[0].points[-1]
    assert lines.points[pieces[0].points[0], 0] > 8.9
    lifter = Lifter(v, np.tile([0.0, 0.0, 1.0], (len(v), 1)))
    linked = link_pieces(lines, pieces, v, f, mesh_graph(v, f), np.full(len(lines.points), 1.5),
                         lifter, 0.9)
    assert linked.extrusion_starts == 1
    assert np.all(linked.extrude)
    assert np.all(np.diff(linked.path) >= 0)


def test_far_lines_get_lifted_travel(disc: tuple[np.ndarray, np.ndarray]) -> None:
    v, f = disc
    lines = _segments(v, f, [-6.0, -4.8, 5.0, 6.2], -3.0, 3.0)
    pieces = order_lines(lines, np.array([-3.0, -7.0, 0.0]))
    # zig-zag: every other line reversed
    ends = [lines.points[p.points[0], 0] for p in pieces]
    assert ends[0] < 0 < ends[1] and ends[1] * ends[2] < 0
    lifter = Lifter(v, np.tile([0.0, 0.0, 1.0], (len(v), 1)))
    linked = link_pieces(lines, pieces, v, f, mesh_graph(v, f), np.full(len(lines.points), 1.2),
                         lifter, 0.9)
    assert linked.extrusion_starts == 2
    trav = ~linked.extrude
    assert np.any(trav)
    assert np.all(linked.points[trav, 2] >= 0.9 - 1e-9)
    assert np.all(linked.face[trav] == -1)
    # travel has its own path id, between the two extrusion paths
    ids = np.unique(linked.path)
    assert len(ids) == 3 and np.all(linked.path[trav] == ids[1])
    dep = deposit_mask(linked.extrude, linked.path)
    assert not np.any(dep[np.flatnonzero(trav)[:-1]])


def test_lifter_clears_a_curved_layer() -> None:
    v, f = disc_mesh(10.0, 1.0)
    v[:, 2] = 5.0 * (1 - (v[:, 0] ** 2 + v[:, 1] ** 2) / 100.0)  # a dome
    from slicer.toolpath.surface import vertex_normals

    n = vertex_normals(v, f)
    n = n * np.sign(n[:, 2:3])
    lifter = Lifter(v, n)
    pa, pb = v[np.argmin(v[:, 0])], v[np.argmax(v[:, 0])]
    pts, nrm = lifter.travel(pa, pb, 0.8, 1.0)
    # straight between the two low ends would cut through the dome; the travel stays above
    _, near = lifter.tree.query(pts)
    h = np.einsum("ij,ij->i", pts - v[near], n[near])
    assert np.all(h >= 0.8 - 1e-6)
    assert pts[:, 2].max() > 5.0
    assert np.allclose(np.linalg.norm(nrm, axis=1), 1.0)


def test_zigzag_order_joins_parallel_stripes(disc: tuple[np.ndarray, np.ndarray]) -> None:
    v, f = disc
    ys = [-3.0, -1.8, -0.6, 0.6, 1.8, 3.0]
    lines = _segments(v, f, ys[::-1][:3] + ys[:3], -4.0, 4.0)  # ids not in spatial order
    reach = np.full(len(lines.points), 1.5)
    # the nozzle is near the middle stripe: starting there strands one side
    pieces = order_lines(lines, np.array([-4.0, 0.7, 0.0]), reach=reach)
    ys_order = [lines.points[p.points[0], 1] for p in pieces]
    assert sorted(ys_order) == sorted(ys)
    # consecutive stripes are neighbours and alternate direction (a zig-zag)
    assert np.allclose(np.abs(np.diff(ys_order)), 1.2)
    xs = [lines.points[p.points[0], 0] for p in pieces]
    assert np.all(np.array(xs[:-1]) * np.array(xs[1:]) < 0)
    lifter = Lifter(v, np.tile([0.0, 0.0, 1.0], (len(v), 1)))
    linked = link_pieces(lines, pieces, v, f, mesh_graph(v, f), np.full(len(lines.points), 1.25),
                         lifter, 0.9)
    assert linked.extrusion_starts == 1
    # connectors: the 5 U-turns between the 6 stripes, nothing on a line
    con = linked.connector_segments()
    on_line = (linked.piece[1:] == linked.piece[:-1]) & (linked.piece[1:] >= 0)
    assert not np.any(con & on_line)
    assert np.count_nonzero(con & ~np.r_[con[1:], False]) == 5  # runs of connector segments
    seg = np.linalg.norm(np.diff(linked.points, axis=0), axis=1)
    assert seg[con].sum() == pytest.approx(5 * 1.2, rel=0.05)


def test_join_factor_decides_what_extrudes(disc: tuple[np.ndarray, np.ndarray]) -> None:
    v, f = disc
    lines = _segments(v, f, [-1.5, 1.5], -3.0, 3.0)  # 3 mm apart, W 1.2: 2.5 W
    lifter = Lifter(v, np.tile([0.0, 0.0, 1.0], (len(v), 1)))
    starts = []
    for factor in (2.0, 3.0):
        pieces = order_lines(lines, np.array([-3.0, -2.0, 0.0]),
                             reach=np.full(len(lines.points), factor * 1.2))
        linked = link_pieces(lines, pieces, v, f, mesh_graph(v, f),
                             np.full(len(lines.points), 1.2), lifter, 0.9, factor)
        starts.append(linked.extrusion_starts)
        assert np.all(linked.points[~linked.extrude, 2] >= 0.9 - 1e-9)
    assert starts == [2, 1]
