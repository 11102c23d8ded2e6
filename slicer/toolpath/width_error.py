"""Measured toolpath spacing and the width error |spacing - W| / W (design.md report keys;
W the mean of the two neighbouring lines' widths, ``width_measure.measure_width``)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from core.errors import InputError
from core.tolerance import tol

BAND_PIECES = 64  # boundary pieces searched for both sides of a band (band_width)


class WidthError(NamedTuple):
    """Percentiles of the relative width error |spacing - W| / W (dimensionless)."""

    p50: float
    p90: float
    p95: float

    def as_dict(self) -> dict[str, float]:
        """The report.json form: {"p50": ..., "p90": ..., "p95": ...}."""
        return {"p50": self.p50, "p90": self.p90, "p95": self.p95}


def _arc_length(points: NDArray[np.float64], line: NDArray[np.int32]
                ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(P,) arc length from the start of each point's line and (P,) total length of its line."""
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    seg[line[1:] != line[:-1]] = 0.0
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    start = np.flatnonzero(np.concatenate([[True], line[1:] != line[:-1]]))
    first = np.repeat(start, np.diff(np.concatenate([start, [len(line)]])))
    s = cum - cum[first]
    total = np.zeros(int(line.max()) + 1)
    np.maximum.at(total, line, s)
    return s, total[line]


class LineNeighbours(NamedTuple):
    """Each line point's neighbouring line: the distance to it and where it is met.

    spacing: (P,) float64 mm, distance to the neighbouring line, NaN where none was found.
    near, far: (P,) int64, the neighbour's foot lies on the segment from point ``near`` to
        point ``far`` (equal where the foot is a point), index into the points.
    t: (P,) float64 in [0, 1], the foot's position from ``near`` to ``far``.
    """

    spacing: NDArray[np.float64]
    near: NDArray[np.int64]
    far: NDArray[np.int64]
    t: NDArray[np.float64]

    def at_foot(self, values: NDArray[np.float64]) -> NDArray[np.float64]:
        """(P,) ``values`` (one per line point) interpolated at each point's foot on the
        neighbouring line (the point's own value where it has no neighbour)."""
        v = np.asarray(values, dtype=np.float64)
        out = (1.0 - self.t) * v[self.near] + self.t * v[self.far]
        return np.where(np.isfinite(self.spacing), out, v)


def line_spacing(points: NDArray[np.float64], line: NDArray[np.integer],
                 normals: NDArray[np.float64] | None = None, k: int = 24,
                 closed: NDArray[np.bool_] | None = None, max_k: int = 768
                 ) -> NDArray[np.float64]:
    """(P,) float64 mm, distance from each line point to the neighbouring line
    (``line_neighbours(...).spacing``)."""
    return line_neighbours(points, line, normals, k, closed, max_k).spacing


def line_neighbours(points: NDArray[np.float64], line: NDArray[np.integer],
                    normals: NDArray[np.float64] | None = None, k: int = 24,
                    closed: NDArray[np.bool_] | None = None, max_k: int = 768
                    ) -> LineNeighbours:
    """Each line point's distance to the neighbouring line, and the foot there.

    points: (P, 3) float64 mm, polylines stored consecutively; line: (P,) int polyline id.
    The neighbour is the nearest segment of another line, or of the same line when the two
    points are far apart along it (arc length > 3x the chord: a line folding back is its own
    neighbour). normals: optional (P, 3) unit surface normals; the offset along the normal
    is then ignored (distance within the layer). closed: optional (L,) bool, closed lines
    also join their last point to their first. Candidates are the k nearest samples, doubled
    up to max_k for points whose candidates all lie on their own stretch of line; points
    still without a neighbour get NaN.
    """
    p = np.asarray(points, dtype=np.float64)
    ln = np.asarray(line, dtype=np.int64)
    if p.ndim != 2 or p.shape[1] != 3 or ln.shape != (len(p),):
        raise InputError("line_spacing needs points (P, 3) and line (P,)",
                         "pass SurfaceLines.points and SurfaceLines.line")
    n_pts = len(p)
    out = np.full(n_pts, np.nan)
    own = np.arange(n_pts)
    if n_pts < 2:
        return LineNeighbours(out, own, own, np.zeros(n_pts))
    s, total = _arc_length(p, ln.astype(np.int32))
    is_closed = np.zeros(int(ln.max()) + 1, dtype=bool)
    if closed is not None:
        is_closed[: len(closed)] = closed
    tree = cKDTree(p)
    j = np.zeros(n_pts, dtype=np.int64)
    has = np.zeros(n_pts, dtype=bool)
    todo = np.arange(n_pts)
    kk = min(k, n_pts)
    while len(todo):  # densely sampled lines may need more candidates: double k for those
        dist, idx = tree.query(p[todo], k=kk)
        same = ln[idx] == ln[todo][:, None]
        gap = np.abs(s[idx] - s[todo][:, None])
        closed_t = is_closed[ln[todo]][:, None]
        gap = np.where(closed_t, np.minimum(gap, total[todo][:, None] - gap), gap)
        folded = same & (gap > 3.0 * dist)
        ok = ~same | folded
        found = ok.any(axis=1)
        j[todo[found]] = idx[found, np.argmax(ok[found], axis=1)]
        has[todo[found]] = True
        if kk >= min(max_k, n_pts):
            break
        todo = todo[~found]
        kk = min(2 * kk, max_k, n_pts)
    # refine: distance to the two segments around the neighbour sample
    best = np.linalg.norm(p[j] - p, axis=1)
    # neighbours of sample j along its line; closed lines wrap around
    head = np.flatnonzero(np.concatenate([[True], ln[1:] != ln[:-1]]))
    tail = np.concatenate([head[1:] - 1, [n_pts - 1]])
    first = np.repeat(head, tail - head + 1)
    last = np.repeat(tail, tail - head + 1)
    wrap = is_closed[ln]
    prev_i = np.where(j > first[j], j - 1, np.where(wrap[j], last[j], j))
    next_i = np.where(j < last[j], j + 1, np.where(wrap[j], first[j], j))
    far = j.copy()
    foot_t = np.zeros(n_pts)
    for nb, valid in ((prev_i, prev_i != j), (next_i, next_i != j)):
        a, b = p[j], p[nb]
        ab = b - a
        t = np.clip(np.einsum("ij,ij->i", p - a, ab)
                    / np.maximum(np.einsum("ij,ij->i", ab, ab), tol.zero), 0.0, 1.0)
        d = p - (a + t[:, None] * ab)
        if normals is not None:
            d = d - np.einsum("ij,ij->i", d, normals)[:, None] * normals
        dd = np.linalg.norm(d, axis=1)
        closer = valid & (dd < best)
        best = np.where(closer, dd, best)
        far = np.where(closer, nb, far)
        foot_t = np.where(closer, t, foot_t)
    if normals is not None:
        d0 = p[j] - p
        d0 = np.linalg.norm(d0 - np.einsum("ij,ij->i", d0, normals)[:, None] * normals, axis=1)
        closer = d0 < best
        best = np.where(closer, d0, best)
        foot_t = np.where(closer, 0.0, foot_t)
    out[has] = best[has]
    return LineNeighbours(out, np.where(has, j, own), np.where(has, far, own),
                          np.where(has, foot_t, 0.0))


def band_width(points: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64],
               k: int = BAND_PIECES) -> NDArray[np.float64]:
    """(P,) float64 mm, width of the band through each point: its distance to the nearest
    boundary segment plus that to the nearest one on the other side (the feet in opposite
    half-spaces), NaN where the other side is not among the k nearest pieces.

    points: (P, 3) mm, e.g. a lone line filling a thin band; a, b: (B, 3) mm ends of the
    band's boundary segments.
    """
    from slicer.toolpath.eikonal import nearest_feet, split_segments

    x = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.full(len(x), np.nan)
    if len(x) == 0 or len(a) == 0:
        return out
    dist, foot, _ = nearest_feet(x, *split_segments(a, b), k)
    first = np.argmin(dist, axis=1)
    rows = np.arange(len(x))
    toward = foot[rows, first] - x  # (P, 3) towards the nearest boundary
    side = np.einsum("pkj,pj->pk", foot - x[:, None, :], toward)
    other = np.where(side < 0.0, dist, np.inf).min(axis=1)
    ok = np.isfinite(other)
    out[ok] = dist[rows, first][ok] + other[ok]
    return out


def width_error(spacing: NDArray[np.float64], target: NDArray[np.float64] | float
                ) -> WidthError:
    """p50, p90, p95 of |spacing - W| / W over points with a measured spacing."""
    sp = np.asarray(spacing, dtype=np.float64)
    w = np.broadcast_to(np.asarray(target, dtype=np.float64), sp.shape)
    ok = np.isfinite(sp) & (w > 0)
    if not ok.any():
        return WidthError(float("nan"), float("nan"), float("nan"))
    err = np.abs(sp[ok] - w[ok]) / w[ok]
    p50, p90, p95 = np.percentile(err, [50, 90, 95])
    return WidthError(float(p50), float(p90), float(p95))
