"""Iso-lines of per-vertex scalars on a triangle mesh, and chaining of line segments.

Segments are extracted for all (face, iso-value) pairs at once; every segment end is a node
keyed by (mesh edge, crossing index on that edge), so the two faces sharing an edge produce the
same node and chaining is a walk over a graph of maximum degree two.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from slicer.toolpath.lines import SurfaceLines, empty_lines
from slicer.toolpath.surface import edge_topology


class Nodes(NamedTuple):
    """Segment end points on mesh edges, before chaining.

    key:   (Q,) int64, unique node key (edge id * stride + crossing index).
    point: (Q, 3) float64, mm.
    face:  (Q,) int32, a face containing the point.
    bary:  (Q, 3) float64, barycentric coordinates in that face.
    """

    key: NDArray[np.int64]
    point: NDArray[np.float64]
    face: NDArray[np.int32]
    bary: NDArray[np.float64]


def chain_segments(seg: NDArray[np.int64], n_nodes: int
                   ) -> tuple[NDArray[np.int64], NDArray[np.int32], NDArray[np.bool_]]:
    """Chain undirected segments (S, 2) over node ids [0, n_nodes) into polylines.

    Returns (order (P,) node ids in line order, line (P,) int32 line id, closed (L,) bool).
    Open chains start at a degree-1 node; cycles start at their lowest node id. A node of
    degree > 2 (never produced by a manifold mesh) keeps its first two segments. O(P).
    """
    if len(seg) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int32), np.zeros(0, bool)
    ends = np.concatenate([seg[:, 0], seg[:, 1]])
    other = np.concatenate([seg[:, 1], seg[:, 0]])
    srt = np.argsort(ends, kind="stable")
    deg = np.bincount(ends, minlength=n_nodes)
    first = np.concatenate([[0], np.cumsum(deg)[:-1]])
    nb0 = np.full(n_nodes, -1, dtype=np.int64)
    nb1 = np.full(n_nodes, -1, dtype=np.int64)
    has = deg >= 1
    nb0[has] = other[srt][first[has]]
    two = deg >= 2
    nb1[two] = other[srt][first[two] + 1]
    n0, n1 = nb0.tolist(), nb1.tolist()
    visited = bytearray(n_nodes)
    order: list[int] = []
    line: list[int] = []
    closed: list[bool] = []
    starts = np.concatenate([np.flatnonzero(deg == 1), np.flatnonzero(deg >= 2)]).tolist()
    for s in starts:  # graph walk: every node is visited once
        if visited[s]:
            continue
        lid = len(closed)
        prev, v = -1, s
        while True:
            visited[v] = 1
            order.append(v)
            line.append(lid)
            nxt = n0[v] if n0[v] != prev else n1[v]
            if nxt < 0 or visited[nxt]:
                break
            prev, v = v, nxt
        # a chain that started at a degree-2 node and ends next to its start is a loop
        closed.append(bool(deg[s] >= 2 and (n0[v] == s or n1[v] == s) and v != s))
    return (np.asarray(order, dtype=np.int64), np.asarray(line, dtype=np.int32),
            np.asarray(closed, dtype=bool))


def lines_from_segments(nodes: Nodes, seg_keys: NDArray[np.int64],
                        min_points: int = 2) -> SurfaceLines:
    """Chain segments given as pairs of node keys (S, 2) into SurfaceLines.

    ``nodes`` holds one entry per segment end (duplicates allowed); lines with fewer than
    ``min_points`` points are dropped.
    """
    if len(seg_keys) == 0:
        return empty_lines()
    ukey, first = np.unique(nodes.key, return_index=True)
    seg = np.searchsorted(ukey, seg_keys)
    seg = seg[seg[:, 0] != seg[:, 1]]
    order, line, closed = chain_segments(seg, len(ukey))
    counts = np.bincount(line, minlength=len(closed))
    keep_line = counts >= min_points
    keep = keep_line[line]
    order, line = order[keep], line[keep]
    renum = np.cumsum(keep_line) - 1
    src = first[order]
    return SurfaceLines(
        points=nodes.point[src],
        face=nodes.face[src].astype(np.int32),
        bary=nodes.bary[src],
        line=renum[line].astype(np.int32),
        closed=closed[keep_line],
    )


def iso_segments(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                 values: NDArray[np.float64], levels: NDArray[np.float64]
                 ) -> tuple[Nodes, NDArray[np.int64]]:
    """Segments of the iso-lines u = c for all levels c, vectorised over (face, level) pairs.

    A vertex counts as above a level when u >= c, so every face crossed by a level has exactly
    two crossed sides. Returns the segment-end nodes (2 per segment) and segment keys (S, 2).
    """
    f = np.asarray(faces, dtype=np.int64)
    u = np.asarray(values, dtype=np.float64)
    lv = np.sort(np.asarray(levels, dtype=np.float64))
    uf = u[f]
    lo = np.searchsorted(lv, uf.min(axis=1), side="right")
    hi = np.searchsorted(lv, uf.max(axis=1), side="right")
    count = hi - lo
    fid = np.repeat(np.arange(len(f)), count)
    lid = np.repeat(lo - np.cumsum(np.concatenate([[0], count[:-1]])), count) + np.arange(
        count.sum())
    c = lv[lid]
    ua = uf[fid]
    above = ua >= c[:, None]
    crossed = above != np.roll(above, -1, axis=1)  # side k: corners k, k+1
    side = np.nonzero(crossed)[1].reshape(-1, 2)  # exactly two sides per pair
    topo = edge_topology(f)
    stride = len(lv) + 1
    pts, bary, keys = [], [], []
    rows = np.arange(len(fid))
    for s in range(2):
        k = side[:, s]
        k1 = (k + 1) % 3
        a = ua[rows, k]
        b = ua[rows, k1]
        t = (c - a) / (b - a)
        bc = np.zeros((len(fid), 3))
        bc[rows, k] = 1.0 - t
        bc[rows, k1] = t
        p = vertices[f[fid]]
        pts.append(np.einsum("ij,ijk->ik", bc, p))
        bary.append(bc)
        keys.append(topo.face_edge[fid, k] * stride + lid)
    nodes = Nodes(key=np.concatenate(keys), point=np.concatenate(pts),
                  face=np.concatenate([fid, fid]).astype(np.int32), bary=np.concatenate(bary))
    return nodes, np.stack(keys, axis=1)


def iso_lines(vertices: NDArray[np.float64], faces: NDArray[np.integer],
              values: NDArray[np.float64], levels: NDArray[np.float64]) -> SurfaceLines:
    """Ordered polylines of u = c for every c in ``levels``; closed loops are flagged."""
    if len(levels) == 0:
        return empty_lines()
    nodes, seg = iso_segments(vertices, faces, values, levels)
    return lines_from_segments(nodes, seg)


def periodic_face_segments(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                           corner: NDArray[np.float64], period: float,
                           active: NDArray[np.bool_] | None = None, stride: int | None = None
                           ) -> tuple[Nodes, NDArray[np.int64]]:
    """Segments of corner-value = N * period (all integers N) with per-face corner values.

    corner: (m, 3) float64, a linear function on each face given by its corner values (e.g. an
    unwrapped phase); neighbouring faces may disagree by a multiple of ``period`` and by sign,
    but must agree on the difference along their shared edge up to sign. A crossing's node key
    is (edge, rank of the crossing counted from the edge's lower vertex id), which both faces
    compute alike. active: optional (m,) bool, faces that may emit segments. stride: key
    stride (> crossings per edge), computed from ``corner`` when not given.
    """
    f = np.asarray(faces, dtype=np.int64)
    m = len(f)
    act = np.ones(m, dtype=bool) if active is None else np.asarray(active, dtype=bool)
    cv = np.asarray(corner, dtype=np.float64) / period
    lo = np.floor(cv.min(axis=1)).astype(np.int64) + 1
    hi = np.floor(cv.max(axis=1)).astype(np.int64)
    count = np.where(act, np.maximum(hi - lo + 1, 0), 0)
    fid = np.repeat(np.arange(m), count)
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    level = (np.repeat(lo - start, count) + np.arange(count.sum())).astype(np.float64)
    ua = cv[fid]
    above = ua >= level[:, None]
    crossed = above != np.roll(above, -1, axis=1)
    side = np.nonzero(crossed)[1].reshape(-1, 2)
    topo = edge_topology(f)
    if stride is None:
        span = np.abs(cv[:, [1, 2, 0]] - cv).max() if m else 0.0
        stride = int(np.ceil(span)) + 2
    rows = np.arange(len(fid))
    pts, bary, keys = [], [], []
    for s in range(2):
        k = side[:, s]
        k1 = (k + 1) % 3
        a = ua[rows, k]
        b = ua[rows, k1]
        t = (level - a) / (b - a)
        bc = np.zeros((len(fid), 3))
        bc[rows, k] = 1.0 - t
        bc[rows, k1] = t
        pts.append(np.einsum("ij,ijk->ik", bc, vertices[f[fid]]))
        bary.append(bc)
        # rank along the edge from its lower vertex id: invariant to shifts and sign flips
        low_is_k = f[fid, k] < f[fid, k1]
        p_low = np.where(low_is_k, a, b)
        rank = np.floor(np.abs(level - p_low)).astype(np.int64)
        keys.append(topo.face_edge[fid, k] * stride + np.minimum(rank, stride - 1))
    nodes = Nodes(key=np.concatenate(keys), point=np.concatenate(pts),
                  face=np.concatenate([fid, fid]).astype(np.int32), bary=np.concatenate(bary))
    return nodes, np.stack(keys, axis=1)


def edge_crossings(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                   fid: NDArray[np.int64], side: NDArray[np.int64],
                   start: NDArray[np.float64], end: NDArray[np.float64], period: float,
                   stride: int) -> tuple[Nodes, NDArray[np.int64]]:
    """Crossings of value = N * period along single face sides, keyed like the segments.

    For each (face fid[i], side side[i]) the value runs linearly from start[i] at corner
    side[i] to end[i] at corner side[i] + 1. Returns one node per crossing (keys as in
    ``periodic_face_segments`` with the same ``stride``) and (Q,) the row i it came from.
    """
    f = np.asarray(faces, dtype=np.int64)
    a = np.asarray(start, dtype=np.float64) / period
    b = np.asarray(end, dtype=np.float64) / period
    lo = np.floor(np.minimum(a, b)).astype(np.int64) + 1
    hi = np.floor(np.maximum(a, b)).astype(np.int64)
    count = np.maximum(hi - lo + 1, 0)
    row = np.repeat(np.arange(len(a)), count)
    first = np.concatenate([[0], np.cumsum(count)[:-1]])
    level = (np.repeat(lo - first, count) + np.arange(count.sum())).astype(np.float64)
    ff, k = fid[row], side[row]
    k1 = (k + 1) % 3
    t = (level - a[row]) / (b[row] - a[row])
    rows = np.arange(len(row))
    bc = np.zeros((len(row), 3))
    bc[rows, k] = 1.0 - t
    bc[rows, k1] = t
    pts = np.einsum("ij,ijk->ik", bc, vertices[f[ff]])
    low_is_k = f[ff, k] < f[ff, k1]
    p_low = np.where(low_is_k, a[row], b[row])
    rank = np.floor(np.abs(level - p_low)).astype(np.int64)
    topo = edge_topology(f)
    key = topo.face_edge[ff, k] * stride + np.minimum(rank, stride - 1)
    return Nodes(key=key, point=pts, face=ff.astype(np.int32), bary=bc), row
