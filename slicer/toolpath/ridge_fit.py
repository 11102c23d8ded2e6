"""Contours fitted to the local width of any component: a whole number of lines across it.

Eq. 9's iso-lines of the boundary distance d at (k + 1/2) tau W fit a region only where its
width is a whole number of spacings. Where fronts grown from different stretches of the
boundary meet (the ridge of d: a neck, a bar, the wall between two holes, the strip between
a hole and the rim) the last lines stand at an arbitrary distance from the ridge: a neck
2.8 W wide holds lines at 0.5 and 1.5 W from each side, 0.2 W apart, and a bar 2.5 W wide
gets a ring collapsed onto itself.

Here every vertex reads the width b of the part across it (``band_across``: along the ray
straight away from its nearest boundary point, to where the boundary is met again), and
the band fit of ``contours.two_sided_contour_lines`` applies to every component, one
boundary loop or many: n = round(b / spacing) lines at the even pitch b / n, floor(n / 2)
of them at d = (k + 1/2) pitch from the boundary and, for odd n, one on the ridge itself
(the medial line, ``medial.medial_lines``). On a band between two loops this is the
two-sided fit; on a disc the rings spaced to fill its radius exactly. The strategy keeps
these lines where they keep their spacing better than eq. 9's (``candidate_choice.py``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from core.tolerance import tol
from slicer.toolpath.contours import BRANCH_ROOM, band_pitch
from slicer.toolpath.eikonal import nearest_feet, split_segments
from slicer.toolpath.isolines import iso_lines
from slicer.toolpath.lines import SurfaceLines, empty_lines, merge_lines
from slicer.toolpath.medial import medial_lines
from slicer.toolpath.perimeter import clip_lines
from slicer.toolpath.surface import (
    boundary_edges,
    boundary_loops,
    check_mesh,
    edge_topology,
    vertex_normals,
)

FLARE = 1.0  # mm of width per mm along the part: where a ray reads more than a vertex near
# the ridge allows at this rate, the ray ran along the part (the end of a bar) or grazed it
OFF_RAY = 0.5  # a boundary crossing counts where it lies within this x its distance of the
# ray's line, along the normal (a layer curving by up to 27 deg between the two sides)
RAY_SAMPLES = 12  # points of each ray where the boundary distance is read
SLACK = 0.25  # the blend's count holds where the part itself is at most this x spacing short
# of it (past the usual rounding); narrower, the lines it carries in are dropped
LOCAL_ROUNDS = 3  # neighbour averagings of the width read per vertex (its ray noise)
CHUNK = 2_000_000  # ray-segment pairs tested at once (memory)


def band_across(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                distance: NDArray[np.float64]) -> NDArray[np.float64]:
    """(n,) float64 mm, the width of the component across each vertex: its boundary
    distance plus how far on, straight away from its nearest boundary point, the boundary
    is met again.

    That is the band a line through the vertex belongs to (the two-sided fit's
    d_outer + d_inner, here for any number of boundary loops): across a bar or a neck its
    width, on a disc its diameter, in a convex corner the width of the bar the corner
    turns (the ray runs along the other side, not into it). On a curved layer, where the
    chord is shorter than the way over the surface, at least twice the largest boundary
    distance along the ray (a cap's diameter over its dome). Euclidean, in the plane of
    the ray and the vertex normal (a layer is nearly flat across one band). Where the ray
    runs along the part (a bar's end) the reading is limited from the ridge (``FLARE``),
    but never below twice the boundary distance where the ray crosses the ridge (a body
    beside a neck keeps its width). A boundary vertex takes the mean of its interior
    neighbours'.
    distance: (n,) float64 mm boundary distance (``geodesic.boundary_distance``).
    """
    check_mesh(vertices, faces)
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    d = np.asarray(distance, dtype=np.float64)
    bnd = boundary_edges(f)
    out = 2.0 * d
    if len(bnd) == 0 or len(f) == 0:
        return out
    a, b = v[bnd[:, 0]], v[bnd[:, 1]]
    pa, pb = split_segments(a, b)
    used = np.unique(f)
    on_boundary = np.zeros(len(v), dtype=bool)
    on_boundary[bnd.ravel()] = True
    ids = used[~on_boundary[used]]
    normal = vertex_normals(v, f)
    e = edge_topology(f).edges
    edge = float(np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1).mean()) if len(e) else 0.0
    ahead = np.zeros(len(ids))
    ridge = np.zeros(len(ids))
    if len(ids):
        dist, foot, _ = nearest_feet(v[ids], pa, pb, 16)
        nearest = foot[np.arange(len(ids)), np.argmin(dist, axis=1)]
        u = v[ids] - nearest
        u /= np.maximum(np.linalg.norm(u, axis=1), tol.zero)[:, None]
        cut = np.cross(u, normal[ids])  # normal of the plane holding the ray
        ahead = np.full(len(ids), np.inf)
        step = max(1, CHUNK // max(len(a), 1))
        for lo in range(0, len(ids), step):
            sl = slice(lo, lo + step)
            p0 = v[ids[sl]]
            sa = np.einsum("pk,sk->ps", cut[sl], a) - np.einsum("pk,pk->p", cut[sl], p0)[:, None]
            sb = np.einsum("pk,sk->ps", cut[sl], b) - np.einsum("pk,pk->p", cut[sl], p0)[:, None]
            cross = (sa * sb <= 0.0) & (sa != sb)
            t = np.where(cross, sa / np.where(sa != sb, sa - sb, 1.0), 0.0)
            hit = a[None] + t[..., None] * (b - a)[None]
            along = np.einsum("psk,pk->ps", hit - p0[:, None, :], u[sl])
            # a crossing far off the ray along the normal is another part of a curved
            # layer's boundary, not the one the ray runs into
            off = np.abs(np.einsum("psk,pk->ps", hit - p0[:, None, :], normal[ids[sl]]))
            along = np.where(cross & (along > tol.zero) & (off <= OFF_RAY * along), along,
                             np.inf)
            ahead[sl] = along.min(axis=1)
        ahead = np.where(np.isfinite(ahead), ahead, 0.0)
        # on a curved layer the chord is shorter than the way across over the surface: at
        # least twice the largest boundary distance on the way (the mesh vertex nearest
        # each of RAY_SAMPLES points of the ray)
        frac = (np.arange(RAY_SAMPLES) + 0.5) / RAY_SAMPLES
        x = v[ids][:, None, :] + (ahead[:, None] * frac)[..., None] * u[:, None, :]
        _, near = cKDTree(v[used]).query(x.reshape(-1, 3))
        on_ray = d[used][near].reshape(len(ids), RAY_SAMPLES)
        deepest = on_ray.max(axis=1)
        out[ids] = np.maximum(d[ids] + ahead, 2.0 * np.maximum(deepest, d[ids]))
        ridge = _first_peak(np.column_stack([d[ids], on_ray]), edge)
    # near the ridge (at least 0.4 of its band from the boundary, its ray ran on past the
    # ridge) a reading holds; elsewhere it is at most FLARE x the way from such a vertex
    # more: at the end of a bar the ray runs along the bar and reads its length. A ray
    # that met the boundary before it had come as far as it started from it (the far side
    # of a band is at least as far as the near one) grazed it: the limit alone there
    deep = ids[(d[ids] >= 0.4 * out[ids]) & (d[ids] >= edge) & (ahead >= 0.5 * d[ids])]
    if len(deep):
        limit = _flare_limit(v, e, out, deep)[ids]
        grazed = (ahead < d[ids]) & np.isfinite(limit)
        out[ids] = np.where(grazed, limit, np.minimum(out[ids], limit))
        # ... but never below twice the boundary distance where the ray crosses the ridge
        # (its first peak): the limit from a narrow neck nearby (the strip between a rim
        # and a hole near it) would otherwise lower the wide body beside it, which then
        # gets too few lines and is left bare
        out[ids] = np.where(grazed, out[ids], np.maximum(out[ids], 2.0 * ridge))
    # boundary vertices: the mean of their interior neighbours (a corner vertex with none:
    # of its neighbours along the boundary)
    src = np.concatenate([e[:, 0], e[:, 1]])
    dst = np.concatenate([e[:, 1], e[:, 0]])
    known = ~on_boundary
    for _ in range(2):
        take = on_boundary[src] & known[dst]
        total = np.zeros(len(v))
        count = np.zeros(len(v))
        np.add.at(total, src[take], out[dst[take]])
        np.add.at(count, src[take], 1.0)
        has = on_boundary & ~known & (count > 0)
        out[has] = total[has] / count[has]
        known = known | has
    return out


def _first_peak(along: NDArray[np.float64], drop: float) -> NDArray[np.float64]:
    """(p,) float64 mm, per row of ``along`` ((p, s) float64 mm, the boundary distance at
    s points along a ray, in order) its first peak: the largest value before it first
    falls by more than ``drop`` (sampling noise) below it; the row's maximum if it never
    does. Past that peak the ray has crossed the ridge into the next front (a hole's, or
    a wider body beyond a neck), whose depth is no width of the band it started in."""
    top = np.maximum.accumulate(along, axis=1)
    fell = along < top - drop
    first = np.where(fell.any(axis=1), np.argmax(fell, axis=1), along.shape[1] - 1)
    return np.asarray(top[np.arange(len(along)), first], dtype=np.float64)


def _flare_limit(v: NDArray[np.float64], e: NDArray[np.int64], width: NDArray[np.float64],
                 sources: NDArray[np.int64]) -> NDArray[np.float64]:
    """(n,) float64 mm, min over the ``sources`` w of width(w) + FLARE x the way from w
    along the mesh edges (inf where none is reached)."""
    n = len(v)
    length = np.maximum(np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1), tol.zero)
    src = np.concatenate([e[:, 0], e[:, 1], np.full(len(sources), n)])
    dst = np.concatenate([e[:, 1], e[:, 0], sources])
    # a virtual source joined to every source vertex by its width (over FLARE)
    weight = np.concatenate([length, length, np.maximum(width[sources], tol.zero) / FLARE])
    graph = sp.csr_matrix((weight, (src, dst)), shape=(n + 1, n + 1))
    return np.asarray(FLARE * dijkstra(graph, indices=n)[:n], dtype=np.float64)


def ridge_fitted_lines(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                       distance: NDArray[np.float64], band: NDArray[np.float64],
                       spacing: float,
                       smooth: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None = None,
                       room: float = BRANCH_ROOM, ridge: SurfaceLines | None = None,
                       laid: bool = True) -> tuple[SurfaceLines, NDArray[np.float64]]:
    """Contours with a whole number of lines across the local width ``band``.

    distance: (n,) float64 mm boundary distance; band: (n,) float64 mm, ``band_across``.
    spacing: mm, target pitch (tau W); smooth, room: as ``contours.two_sided_contour_lines``
    (the pitch blended where the count changes, a line starts where it has nearly a full
    pitch of room). ridge: ``medial.medial_lines`` of the surface when the caller has it.
    laid: where a line is dropped for room, the pitch of the lines laid (``_laid_pitch``);
    False: the blended pitch everywhere (both are tried, see ``candidate_choice.py``).
    Returns the lines and (n,) float64 mm, the local pitch they are laid at.
    """
    check_mesh(vertices, faces)
    f = np.asarray(faces, dtype=np.int64)
    d = np.asarray(distance, dtype=np.float64)
    width = np.maximum(np.asarray(band, dtype=np.float64), 2.0 * d)
    pitch, fit = band_pitch(d, width - d, spacing, smooth)
    if ridge is None:
        ridge = medial_lines(np.asarray(vertices, dtype=np.float64), f.astype(np.int32))
    if laid and smooth is not None:
        pitch, fit = _laid_pitch(np.asarray(vertices, dtype=np.float64), f, width, pitch, fit,
                                 room, ridge, smooth)
    n_face = np.maximum(np.floor((fit / pitch)[f].mean(axis=1) + 0.5 - room), 1
                        ).astype(np.int64)
    # ... but never more lines than a part without holes holds where they are laid
    most = np.full(len(d), np.inf)
    if len(boundary_loops(f)) == 1:
        held = _local_ratio(f, width, spacing)
        most = np.maximum(np.floor(held + 0.5 + SLACK), 1.0)
        n_face = np.minimum(n_face, np.maximum(np.floor(held[f].mean(axis=1) + 0.5 + SLACK),
                                               1.0).astype(np.int64))
    phi = d / pitch
    parts: list[SurfaceLines] = []
    maps: list[NDArray[np.int64]] = []
    for k in range(min(int(n_face.max()) // 2, int(np.ceil(phi.max())))):
        sel = np.flatnonzero(n_face // 2 > k)
        part = iso_lines(vertices, f[sel], phi, np.array([k + 0.5]))
        if part.n_lines:
            parts.append(part)
            maps.append(sel)
    if ridge.n_lines and np.any(n_face % 2 == 1):
        # an odd count's middle line on the ridge: the medial line where the count at its
        # vertices is odd (phi = n / 2 there: a quarter pitch beyond the last pair's level)
        n_vertex = np.minimum(np.maximum(np.floor(fit / pitch + 0.5 - room), 1), most)
        middle = clip_lines(ridge, vertices, f.astype(np.int32),
                            phi - np.floor(0.5 * n_vertex) - 0.25, 0.0)
        if middle.n_lines:
            parts.append(middle)
            maps.append(np.arange(len(f)))
    lines = merge_lines(parts, maps) if parts else empty_lines()
    return lines, pitch


def _local_ratio(f: NDArray[np.int64], width: NDArray[np.float64], spacing: float
                 ) -> NDArray[np.float64]:
    """(n,) float64, how many spacings the part is wide across each vertex: its own width
    (``band_across``, averaged with its mesh neighbours LOCAL_ROUNDS times against the
    noise of single rays) over ``spacing``; the most lines it holds there is this rounded
    with SLACK to spare.

    The count blended over PITCH_SMOOTHING spacings (rings stay continuous where it
    changes) also carries a wide body's count into a lobe shorter than the blend: 4 lines,
    two rings and no middle line, in suzanne's ears 3 wide, the outer ring's sides two
    spacings apart. Capped by the lobe's own width: a ring and the middle line. Only
    without holes: where the rings from the rim and the holes meet the cap helped one
    machined plate and cost two others (docs/benchmarks.md, Session 21: caps)."""
    e = edge_topology(f).edges
    n = len(width)
    adj = sp.csr_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]],
                                               np.r_[e[:, 1], e[:, 0]])), shape=(n, n))
    deg = np.asarray(adj.sum(axis=1)).ravel() + 1.0
    local = np.asarray(width, dtype=np.float64)
    for _ in range(LOCAL_ROUNDS):
        local = (adj @ local + local) / deg
    return local / spacing


def _laid_pitch(v: NDArray[np.float64], f: NDArray[np.int64], width: NDArray[np.float64],
                pitch: NDArray[np.float64], fit: NDArray[np.float64], room: float,
                ridge: SurfaceLines,
                smooth: Callable[[NDArray[np.float64]], NDArray[np.float64]],
                ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(n,) float64 mm, the pitch of the lines actually laid, and (n,) float64 mm, the
    width they fill (fit / pitch: the count, as ``band_pitch``'s).

    The blended pitch (``band_pitch``) is that of round(b / spacing) lines, but a line is
    laid only where it has room (floor(blended b / blended pitch + 1/2 - room)): across an
    ellipse 3.6 spacings wide whose ends are narrower the blend reads 3.8 lines, 3 are
    laid at the pitch of 4, 0.9 pitch apart too far and printed too narrow for it
    (``LineSource.width_scale`` follows the pitch). Where a line is dropped so, the pitch
    is blended again from b / the count laid (the counts stay). That count is read at
    each vertex and on the ridge, where a line is added or dropped (its nearest ridge
    point), the larger of the two: read at the vertex alone it changes across a band
    whose blend drifts by a tenth of a line from side to side. Elsewhere the pitch stays
    (rounding also absorbs a band read too wide at a bar's end, which b / n would not).
    """
    ratio = fit / pitch
    count = np.maximum(np.floor(ratio + 0.5 - room), 1.0)
    used = np.unique(f)
    if ridge.n_lines and len(used):
        at = np.einsum("pk,pk->p", ratio[f[ridge.face]], ridge.bary)
        _, near = cKDTree(ridge.points).query(v[used])
        count[used] = np.maximum(count[used], np.floor(at + 0.5 - room)[near])
    dropped = count < np.rint(ratio)
    if not dropped.any():
        return pitch, fit
    laid = np.maximum(smooth(width / count), tol.zero)
    share = np.clip(smooth(dropped.astype(np.float64)), 0.0, 1.0)
    share[dropped] = 1.0
    out = (1.0 - share) * pitch + share * laid
    return out, np.where(dropped, np.maximum(np.floor(ratio + 0.5 - room), 1.0), ratio) * out
