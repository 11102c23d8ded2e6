"""What the slicing field is held to: critical regions collapsed, fixed directions, G0's anchors.

All vertices of one critical region (or of touching regions) share one unknown of g
(``unknown_map``, eq. 7); tets owning a region's boundary face have their v fixed to its growth
direction, and a connected part without any region gets the planar default, +z on its bottom
tets (``constraints``); the harmonic baseline G0 fixes each region to its mean height and
completes parts left flat with their bottom and top (``harmonic_anchors``). Lengths are mm.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from core.tolerance import tol
from slicer.critical import CriticalSelection
from slicer.operators import TetOperators


def unknown_map(n_vertices: int, selection: CriticalSelection) -> tuple[np.ndarray, int]:
    """(V,) int64 unknown index per vertex, regions collapsed; and the number of unknowns."""
    rows = [r.vertices for r in selection.regions]
    cols = [np.full(len(r.vertices), r.vertices[0]) for r in selection.regions]
    if rows:
        i, j = np.concatenate(rows), np.concatenate(cols)
    else:
        i = j = np.zeros(0, dtype=np.int64)
    graph = sp.coo_matrix((np.ones(len(i)), (i, j)), shape=(n_vertices, n_vertices))
    count, labels = connected_components(graph, directed=False)
    return labels.astype(np.int64), int(count)


def vertex_components(ops: TetOperators) -> np.ndarray:
    """(V,) int64 connected-part label per vertex (vertices connected through tets)."""
    _, comp = connected_components(ops.laplacian, directed=False)
    return comp.astype(np.int64)


def mean_edge(ops: TetOperators) -> float:
    """Mean length (mm) of one edge per tet: the mesh's scale for "near the bottom"."""
    return float(np.linalg.norm(ops.vertices[ops.tets[:, 1]] - ops.vertices[ops.tets[:, 0]],
                                axis=1).mean())


def part_extremes(values: np.ndarray, comp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-part min and max of a vertex quantity: ((P,), (P,))."""
    lo = np.full(int(comp.max()) + 1, np.inf)
    hi = np.full(len(lo), -np.inf)
    np.minimum.at(lo, comp, values)
    np.maximum.at(hi, comp, values)
    return lo, hi


def constraints(ops: TetOperators, selection: CriticalSelection,
                 comp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Constrained tets and their fixed vectors: ((T,) bool, (T, 3) float64 unit).

    A connected part of the mesh without any region (the whole mesh when there is none, or
    a stray fragment of the mesher) gets the planar default: its bottom tets grow along +z.
    """
    n = ops.n_tets
    fixed = np.zeros((n, 3))
    if selection.regions:
        tets = np.concatenate([ops.boundary.tet[r.faces] for r in selection.regions])
        grow = np.concatenate([r.growth * ops.boundary.area[r.faces, None]
                               for r in selection.regions])
        np.add.at(fixed, tets, grow)
    tet_part = comp[ops.tets[:, 0]]
    has_region = np.zeros(int(comp.max()) + 1 if len(comp) else 0, dtype=bool)
    has_region[tet_part[np.linalg.norm(fixed, axis=1) > tol.zero]] = True
    bare = ~has_region[tet_part]
    if bare.any():
        # The layers start at the part's bottom, growing along +z.
        z = ops.vertices[:, 2]
        zmin, _ = part_extremes(z, comp)
        bottom = bare & (z[ops.tets].min(axis=1) <= zmin[tet_part] + 0.5 * mean_edge(ops))
        fixed[bottom] = (0.0, 0.0, 1.0)
    norm = np.linalg.norm(fixed, axis=1)
    constrained = norm > tol.zero
    fixed[constrained] /= norm[constrained, None]
    return constrained, fixed


def harmonic_anchors(ops: TetOperators, selection: CriticalSelection, labels: np.ndarray,
                      comp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Dirichlet data of the scalar harmonic G0: (unknown indices, values), both (k,).

    Each critical region's (collapsed) unknown gets the region's area-weighted mean height z.
    In a connected part where that leaves fewer than two distinct values (one region, or none)
    the field would be constant, so the planar default completes it: the part's boundary
    vertices within half an edge of its lowest z (when none of its regions is a start
    surface) and of its highest z (when none is an end surface) get g = z, i.e. layers start
    flat on the build plate / end flat at the top.
    """
    n_parts = int(comp.max()) + 1 if len(comp) else 0
    idx: list[np.ndarray] = []
    val: list[np.ndarray] = []
    part = np.zeros(len(selection.regions), dtype=np.int64)
    for k, r in enumerate(selection.regions):  # loop over regions, not faces
        area = ops.boundary.area[r.faces]
        zc = ops.vertices[ops.boundary.faces[r.faces], 2].mean(axis=1)
        idx.append(labels[r.vertices[:1]])
        val.append(np.array([float((zc * area).sum() / max(float(area.sum()), tol.zero))]))
        part[k] = comp[r.vertices[0]]
    values = np.concatenate(val) if val else np.zeros(0)
    signs = np.array([r.sign for r in selection.regions])
    lo_v, hi_v = np.full(n_parts, np.inf), np.full(n_parts, -np.inf)
    np.minimum.at(lo_v, part, values)
    np.maximum.at(hi_v, part, values)
    scale = max(1.0, float(np.abs(ops.vertices[:, 2]).max()))
    flat = ~(hi_v - lo_v > tol.zero * scale)  # also the parts without any region
    has_start = np.zeros(n_parts, dtype=bool)
    has_end = np.zeros(n_parts, dtype=bool)
    has_start[part[signs < 0]] = True
    has_end[part[signs > 0]] = True
    if flat.any():
        z = ops.vertices[:, 2]
        on_boundary = np.zeros(ops.n_vertices, dtype=bool)
        on_boundary[ops.boundary.faces.ravel()] = True
        zmin, zmax = part_extremes(z, comp)
        half = 0.5 * mean_edge(ops)
        base = on_boundary & (flat & ~has_start)[comp] & (z <= zmin[comp] + half)
        top = on_boundary & (flat & ~has_end)[comp] & (z >= zmax[comp] - half)
        extra = np.flatnonzero(base | top)
        idx.append(labels[extra])
        values = np.concatenate([values, z[extra]])
    unknowns = np.concatenate(idx) if idx else np.zeros(0, dtype=np.int64)
    # A vertex may be picked twice (an anchor on a region): keep its first value (the region's).
    unknowns, first = np.unique(unknowns, return_index=True)
    return unknowns, values[first]
