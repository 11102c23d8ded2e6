"""Coverage: the share of each layer that the deposited bands leave bare or cover twice.

The width error measures the spacing between neighbouring lines; it leaves out connectors,
ends and the boundary. Coverage measures the result: every extruding segment (connectors
included) lays a band of its width W along its path; a point of the layer surface is
*covered* by a segment when its distance to the segment, measured in the surface's tangent
plane (a waypoint flushed or relieved off the layer along its normal still covers the
point under it), is below W / 2. Segments of one path that cover a point within
``SAME_PASS`` x W of arc length of each other are one pass (a band does not overlap itself
at a turn); a point covered by no pass is a *gap*, by two or more an *overlap*.

The layer surface is sampled at random (area-weighted, fixed seed: the same toolpath gives
the same numbers) at about ``SAMPLES_PER_W2`` points per W^2 of area, at most
``MAX_SAMPLES`` per layer; the fractions are area fractions, accurate to about
0.5 / sqrt(samples).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from core.stages import Layers, Toolpath
from core.tolerance import tol
from slicer.toolpath.linking import deposit_mask

SAMPLES_PER_W2 = 6.0  # sample density relative to the layer's median width squared
MAX_SAMPLES = 4_000  # per layer: +-1 % per layer, far tighter over a pattern's layers
MIN_SAMPLES = 400  # per layer with any area
SAME_PASS = 2.0  # arc-length window (x W) inside which one path's segments are one pass
SEED = 20_260_101


class LayerCoverage(NamedTuple):
    """Coverage of every layer.

    Attributes:
        area: (L,) float64, mm^2, layer surface area.
        gap: (L,) float64, area fraction covered by no band (0-1).
        overlap: (L,) float64, area fraction covered by two or more passes (0-1).
        pattern: (L,) int8, the layer's pattern (0 contour, 1 stripe, -1 no waypoints).
        samples: (L,) int64, points sampled on the layer.
    """

    area: NDArray[np.float64]
    gap: NDArray[np.float64]
    overlap: NDArray[np.float64]
    pattern: NDArray[np.int8]
    samples: NDArray[np.int64]

    def summary(self) -> dict[str, object]:
        """report.json's ``toolpath.coverage``: area-weighted gap and overlap per pattern,
        their worst layer, and the per-layer lists."""
        out: dict[str, object] = {}
        for name, code in (("contour", 0), ("stripe", 1)):
            sel = (self.pattern == code) & (self.area > 0)
            if not sel.any():
                out[name] = {"layers": 0, "gap": None, "overlap": None}
                continue
            w = self.area[sel]
            out[name] = {
                "layers": int(sel.sum()),
                "gap": float(np.average(self.gap[sel], weights=w)),
                "overlap": float(np.average(self.overlap[sel], weights=w)),
                "gap_max_layer": float(self.gap[sel].max()),
                "overlap_max_layer": float(self.overlap[sel].max()),
            }
        bare = (self.pattern < 0) & (self.area > 0)
        out["unprinted_layers"] = int(bare.sum())
        out["unprinted_area_fraction"] = float(self.area[bare].sum()
                                               / max(self.area.sum(), tol.tiny))
        out["per_layer"] = {"gap": np.round(self.gap, 4).tolist(),
                            "overlap": np.round(self.overlap, 4).tolist()}
        return out


def _sample_layer(vertices: NDArray[np.float64], faces: NDArray[np.int64], count: int,
                  rng: np.random.Generator) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``count`` area-weighted random points on the triangles and their unit face normals."""
    tri = vertices[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(cross, axis=1)
    pick = rng.choice(len(faces), size=count, p=area2 / area2.sum())
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1.0
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    t = tri[pick]
    points = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
    normal = cross[pick] / np.maximum(area2[pick], tol.tiny)[:, None]
    return points, normal


class _Segments(NamedTuple):
    """Extruding segments of one layer: ends a, b (k, 3) mm, half width (k,) mm, path id
    (k,), arc length of the midpoint along its path (k,) mm, and whether the segment
    continues the previous one / is continued by the next (k,) bool (a joint is rounded, a
    band's first and last end are square: the deposited volume is length x W x H)."""

    a: NDArray[np.float64]
    b: NDArray[np.float64]
    half_width: NDArray[np.float64]
    path: NDArray[np.int64]
    s: NDArray[np.float64]
    joined_before: NDArray[np.bool_]
    joined_after: NDArray[np.bool_]


def _segments(tp: Toolpath, rows: NDArray[np.int64]) -> _Segments:
    """The extruding segments between consecutive waypoints ``rows`` (one layer, in order)."""
    pos = np.asarray(tp.position)[rows]
    path = np.asarray(tp.path)[rows].astype(np.int64)
    dep = deposit_mask(np.asarray(tp.extrude)[rows], path)
    length = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    # arc length along each path (restarts where the path id changes do not matter: passes
    # are only compared within one path id)
    s_end = np.concatenate([[0.0], np.cumsum(length)])
    s_mid = 0.5 * (s_end[1:] + s_end[:-1])
    w = np.asarray(tp.width)[rows]
    half = 0.25 * (w[1:] + w[:-1])
    keep = dep & (length > 0)
    before = np.zeros_like(keep)
    before[1:] = keep[:-1]
    after = np.zeros_like(keep)
    after[:-1] = keep[1:]
    return _Segments(pos[:-1][keep], pos[1:][keep], half[keep], path[:-1][keep], s_mid[keep],
                     before[keep], after[keep])


def _covered_pairs(points: NDArray[np.float64], normal: NDArray[np.float64],
                   seg: _Segments) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """(point index, segment index) of every point within half a width of a segment, the
    distance taken in the point's tangent plane."""
    mid = 0.5 * (seg.a + seg.b)
    half_len = 0.5 * np.linalg.norm(seg.b - seg.a, axis=1)
    radius = float((half_len + seg.half_width).max())
    pairs = cKDTree(points).sparse_distance_matrix(cKDTree(mid), radius, output_type="ndarray")
    i = pairs["i"].astype(np.int64)
    j = pairs["j"].astype(np.int64)
    ab = seg.b[j] - seg.a[j]
    t = np.einsum("ij,ij->i", points[i] - seg.a[j], ab) / np.maximum(
        np.einsum("ij,ij->i", ab, ab), tol.tiny)
    closest = seg.a[j] + np.clip(t, 0.0, 1.0)[:, None] * ab
    d = points[i] - closest
    along = np.einsum("ij,ij->i", d, normal[i])
    tangent_sq = np.einsum("ij,ij->i", d, d) - along**2
    # beyond an end, only a joint with the neighbouring segment is covered (round); the
    # band's own first and last ends are square
    inside = ((t >= 0.0) | seg.joined_before[j]) & ((t <= 1.0) | seg.joined_after[j])
    hit = inside & (tangent_sq < seg.half_width[j] ** 2)
    return i[hit], j[hit]


def _passes(n_points: int, i: NDArray[np.int64], j: NDArray[np.int64], seg: _Segments,
            window: float) -> NDArray[np.int64]:
    """(n_points,) int64, the number of distinct passes covering each point."""
    count = np.zeros(n_points, dtype=np.int64)
    if len(i) == 0:
        return count
    path, s = seg.path[j], seg.s[j]
    order = np.lexsort((s, path, i))
    i, path, s = i[order], path[order], s[order]
    new = np.ones(len(i), dtype=bool)
    new[1:] = (i[1:] != i[:-1]) | (path[1:] != path[:-1]) | (s[1:] - s[:-1] > window)
    np.add.at(count, i[new], 1)
    return count


def layer_coverage(layers: Layers, tp: Toolpath, samples_per_w2: float = SAMPLES_PER_W2,
                   max_samples: int = MAX_SAMPLES) -> LayerCoverage:
    """Gap and overlap of every layer of ``layers`` by the bands of ``tp``'s extruding segments
    (sampled at ``samples_per_w2`` points per W^2, at most ``max_samples`` per layer)."""
    n_layers = int(layers.layer_count)
    area = np.zeros(n_layers)
    gap = np.zeros(n_layers)
    overlap = np.zeros(n_layers)
    pattern = np.full(n_layers, -1, dtype=np.int8)
    samples = np.zeros(n_layers, dtype=np.int64)
    vertices = np.asarray(layers.vertices, dtype=np.float64)
    faces = np.asarray(layers.faces, dtype=np.int64)
    face_layer = np.asarray(layers.face_layer)
    tp_layer = np.asarray(tp.layer)
    face_order = np.argsort(face_layer, kind="stable")
    face_bounds = np.searchsorted(face_layer[face_order], np.arange(n_layers + 1))
    wp_order = np.argsort(tp_layer, kind="stable")  # waypoints keep their print order
    wp_bounds = np.searchsorted(tp_layer[wp_order], np.arange(n_layers + 1))
    rng = np.random.default_rng(SEED)
    for k in range(n_layers):  # one vectorised pass per layer
        f = faces[face_order[face_bounds[k]:face_bounds[k + 1]]]
        if len(f) == 0:
            continue
        tri = vertices[f]
        area[k] = 0.5 * float(np.linalg.norm(
            np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())
        rows = wp_order[wp_bounds[k]:wp_bounds[k + 1]]
        seg = _segments(tp, rows) if len(rows) > 1 else None
        if seg is None or len(seg.a) == 0 or area[k] <= 0:
            gap[k] = 1.0 if area[k] > 0 else 0.0
            continue
        pattern[k] = int(np.bincount(np.asarray(tp.pattern)[rows].astype(np.int64)).argmax())
        w_med = 2.0 * float(np.median(seg.half_width))
        count = int(np.clip(samples_per_w2 * area[k] / max(w_med, tol.floor) ** 2,
                            MIN_SAMPLES, max(max_samples, MIN_SAMPLES)))
        points, normal = _sample_layer(vertices, f, count, rng)
        i, j = _covered_pairs(points, normal, seg)
        passes = _passes(count, i, j, seg, SAME_PASS * w_med)
        gap[k] = float(np.mean(passes == 0))
        overlap[k] = float(np.mean(passes >= 2))
        samples[k] = count
    return LayerCoverage(area=area, gap=gap, overlap=overlap, pattern=pattern, samples=samples)
