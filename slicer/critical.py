"""Critical regions Omega: connected patches of boundary faces selected by normal cones.

A region is one edge-connected patch of boundary faces whose outward normal lies within a
selector's cone (design.md, ``--critical``). The slicing field is constant on each region
(paper eq. 7) and the growth direction there follows the face normal (eq. 6):

* a region whose area-weighted mean outward normal has z >= 0 is an *end* surface (e.g. the
  rim of a socket): layers end there, growth = outward normal;
* otherwise it is a *start* surface (e.g. a bottom): growth = -outward normal (into the part).

Regions that touch share one value of the field (one layer lies on both). A start and an end
surface that touch at a sharp edge (a thin sheet whose top and bottom faces meet, the rim of an
ear: mean outward normals more than 90 deg apart) would make the layers grow out of one and end
on the other at the same value: they fold back between the two, and their printing directions
point downward. The smaller of such a pair is dropped before the field is built, with a note
naming it (``resolve_folds``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from core.tolerance import tol
from slicer.config import CriticalSelector
from slicer.operators import TetOperators

MIN_REGION_FACES = 3
# ``@end``: a patch reaches the part's end along the cone's axis when its furthest vertex
# lies within this fraction of the part's extent along the axis from the part's furthest.
END_TOLERANCE = 0.02


class CriticalRegion(NamedTuple):
    """One critical region Omega.

    Attributes:
        vertices: (k,) int64, mesh vertex indices on the region (sorted, unique).
        faces: (m,) int64, indices into ``TetOperators.boundary``.
        normals: (m, 3) float64, unit outward normal of each face.
        growth: (m, 3) float64, unit growth direction of each face (+normal or -normal).
        sign: float, +1.0 for an end surface (growth = outward normal), -1.0 for a start surface.
        selector: str, the selector text that picked it.
        area: float, mm^2, total face area.
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    growth: np.ndarray
    sign: float
    selector: str
    area: float


class CriticalSelection(NamedTuple):
    """The regions found and what happened on the way.

    Attributes:
        regions: the regions, in selector order, then by decreasing area.
        notes: human-readable notes (dropped tiny patches, selectors with no match).
    """

    regions: tuple[CriticalRegion, ...]
    notes: tuple[str, ...]


def _edge_connected_patches(faces: np.ndarray) -> np.ndarray:
    """Component label per face, faces connected when they share an edge.

    Args:
        faces: (m, 3) int, vertex indices.

    Returns:
        (m,) int64 component labels.
    """
    m = len(faces)
    if m == 0:
        return np.zeros(0, dtype=np.int64)
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1).astype(np.int64)
    owner = np.repeat(np.arange(m, dtype=np.int64), 3)
    n = np.int64(edges.max() + 1)
    key = edges[:, 0] * n + edges[:, 1]
    order = np.argsort(key, kind="stable")
    sk = key[order]
    # Consecutive faces sharing an edge key get linked (a chain suffices for connectivity).
    link = np.flatnonzero(sk[1:] == sk[:-1])
    a, b = owner[order[link]], owner[order[link + 1]]
    graph = sp.coo_matrix((np.ones(len(a)), (a, b)), shape=(m, m))
    _, labels = connected_components(graph, directed=False)
    return labels.astype(np.int64)


def resolve_folds(regions: Sequence[CriticalRegion], vertices: np.ndarray
                  ) -> tuple[tuple[CriticalRegion, ...], tuple[str, ...]]:
    """The regions without those that touch a larger region of the other kind (start vs end)
    at a sharp edge.

    Largest first, a region is kept unless it shares a vertex with a kept region of the
    opposite sign whose mean outward normal lies more than 90 deg from its own; each dropped
    one gets a note naming it (selector, area, centre) and the region it touches.

    Args:
        regions: the selected regions, in their order (kept regions keep it).
        vertices: (V, 3) float64, mm, mesh vertex positions (for the notes).
    """
    if len(regions) < 2 or len({r.sign for r in regions}) < 2:
        return tuple(regions), ()
    owner_of: dict[float, np.ndarray] = {}  # sign -> (V,) index of the kept region, -1
    for sign in (-1.0, 1.0):
        owner_of[sign] = np.full(len(vertices), -1, dtype=np.int64)
    keep = np.zeros(len(regions), dtype=bool)
    notes: list[str] = []
    for k in sorted(range(len(regions)), key=lambda i: -regions[i].area):  # over regions
        r = regions[k]
        touching = np.unique(owner_of[-r.sign][r.vertices])
        # a fold only where the two surfaces meet at an edge sharper than a right angle (their
        # mean outward normals more than 90 deg apart): a bottom and a side share a layer
        opposed = [int(t) for t in touching[touching >= 0]
                   if float(_mean_normal(regions[int(t)]) @ _mean_normal(r)) < -tol.slack]
        if opposed:
            other = regions[opposed[0]]
            there = _where(other, vertices)
            notes.append(
                f"critical region of '{r.selector}' ({_where(r, vertices)}) dropped: it touches "
                f"the larger {_kind(other)} surface of '{other.selector}' ({there}), and one "
                "layer cannot begin on one and end on the other (the layers would fold between "
                "them); a position condition (@z<.., @z>..) on a selector chooses otherwise")
            continue
        keep[k] = True
        owner_of[r.sign][r.vertices] = k
    return tuple(r for r, kept in zip(regions, keep, strict=True) if kept), tuple(notes)


def _mean_normal(region: CriticalRegion) -> np.ndarray:
    """(3,) float64 unit mean outward normal of a region's faces."""
    n = region.normals.mean(axis=0)
    return n / max(float(np.linalg.norm(n)), tol.zero)


def _kind(region: CriticalRegion) -> str:
    return "end" if region.sign > 0 else "start"


def _where(region: CriticalRegion, vertices: np.ndarray) -> str:
    centre = vertices[region.vertices].mean(axis=0)
    return (f"{_kind(region)}, {region.area:.0f} mm^2 at ({centre[0]:.1f}, {centre[1]:.1f}, "
            f"{centre[2]:.1f}) mm")


def select_critical_regions(
    ops: TetOperators,
    selectors: Sequence[CriticalSelector],
    min_faces: int = MIN_REGION_FACES,
    folds: bool = True,
) -> CriticalSelection:
    """Split the boundary faces within each selector's cone into edge-connected regions.

    Args:
        ops: the mesh operators (boundary faces with outward normals).
        selectors: the parsed selectors.
        min_faces: patches with fewer faces are dropped (noted in ``notes``).
        folds: drop the smaller of a touching start and end region (``resolve_folds``).

    Returns:
        The regions and notes. A face matched by several selectors belongs to the first.
    """
    bnd = ops.boundary
    taken = np.zeros(len(bnd), dtype=bool)
    regions: list[CriticalRegion] = []
    notes: list[str] = []
    for sel in selectors:
        axis = np.asarray(sel.direction, dtype=np.float64)
        axis = axis / np.linalg.norm(axis)
        cos_cone = np.cos(np.radians(sel.cone_deg))
        chosen = np.flatnonzero((bnd.normal @ axis >= cos_cone) & ~taken)
        if len(chosen) == 0:
            notes.append(f"critical selector '{sel.text}' matched no boundary face")
            continue
        taken[chosen] = True
        labels = _edge_connected_patches(bnd.faces[chosen])
        counts = np.bincount(labels)
        order = np.argsort(labels, kind="stable")
        starts = np.concatenate([[0], np.cumsum(counts)])
        found: list[CriticalRegion] = []
        dropped = 0
        elsewhere = 0
        not_end: list[float] = []
        along = ops.vertices @ axis
        end_level = float(along.max()) - END_TOLERANCE * float(np.ptp(along))
        for lab in range(len(counts)):  # loop over patches, not faces
            idx = chosen[order[starts[lab]:starts[lab + 1]]]
            if len(idx) < min_faces:
                dropped += 1
                continue
            normals = bnd.normal[idx]
            area = bnd.area[idx]
            if sel.at_end and float(along[bnd.faces[idx]].max()) < end_level:
                not_end.append(float(area.sum()))
                taken[idx] = False
                continue
            if sel.where:
                centre = (ops.vertices[bnd.faces[idx]].mean(axis=1) * area[:, None]).sum(
                    axis=0) / max(float(area.sum()), tol.tiny)
                if not sel.accepts(centre):
                    elsewhere += 1
                    taken[idx] = False  # a later selector may still take these faces
                    continue
            mean_normal = (normals * area[:, None]).sum(axis=0)
            sign = 1.0 if mean_normal[2] >= 0 else -1.0
            found.append(
                CriticalRegion(
                    vertices=np.unique(bnd.faces[idx]),
                    faces=idx,
                    normals=normals,
                    growth=sign * normals,
                    sign=sign,
                    selector=sel.text,
                    area=float(area.sum()),
                )
            )
        if dropped:
            notes.append(
                f"critical selector '{sel.text}': dropped {dropped} patch(es) with fewer than "
                f"{min_faces} faces"
            )
        if elsewhere:
            notes.append(f"critical selector '{sel.text}': left out {elsewhere} patch(es) "
                         "outside its @ conditions")
        if not_end:
            notes.append(f"critical selector '{sel.text}': left out {len(not_end)} patch(es) "
                         f"({sum(not_end):.0f} mm^2) away from the part's end along its axis")
        if (sel.where or sel.at_end) and not found:
            notes.append(f"critical selector '{sel.text}' kept no patch")
        found.sort(key=lambda r: -r.area)
        regions.extend(found)
    if folds:
        kept, fold_notes = resolve_folds(regions, ops.vertices)
        return CriticalSelection(regions=kept, notes=(*notes, *fold_notes))
    return CriticalSelection(regions=tuple(regions), notes=tuple(notes))
