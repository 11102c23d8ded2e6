"""Curved layers: iso-values of the slicing field and marching-tetrahedra extraction.

* ``layer_spacing``: slabs of the field about delta thick, each layer the iso-surface through
  the middle of its slab, so the layers fill the part evenly (mean height delta' / delta of
  the target, reported as ``mean_height_mm``). The value of g on a critical region inside the
  range (paper eq. 7), a cavity's floor or ceiling or the top of a branch, is made a slab
  boundary and each interval between such values gets a whole number of equal slabs: the
  surface is then the top or bottom of a whole layer, not somewhere inside a slab.
* ``extract_layers``: the stage entry point: spacing, extraction, the critical-region and
  layer-height checks, in one ``LayerExtraction``.
* ``iso_surfaces``: marching tetrahedra, one layer at a time, vertices welded on the crossed
  tet edges, faces oriented along increasing g; per vertex the direction (normalised
  area-weighted mean gradient) and the height H = slab thickness / |that gradient| (mm).
* ``match_slab_heights``: H scaled per layer so its integral equals the exact volume of the
  layer's slab (``slicer.slabs``), where the first-order H is off because |grad g| changes
  across the slab.
* ``layer_gap``: the measured distance from layer k's vertices to layer k + 1's surface, to
  check H against geometry.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from core.errors import InputError
from core.progress import NullProgress, Progress
from core.stages import Field, Layers, TetMesh
from core.tolerance import tol
from slicer.config import SlicingConfig
from slicer.field import FieldResult
from slicer.operators import TET_EDGES, TetOperators, build_operators
from slicer.slabs import height_integral, slab_height_scale, slab_volumes


class LayerSpacing(NamedTuple):
    """How the iso-values were chosen.

    Attributes:
        iso: (L,) float64, iso-values in increasing order (field units), each the middle of
            its slab.
        delta: float, requested spacing (gives the target mean height exactly).
        delta_used: float, delta' = (g_max - g_min) / L, the mean slab thickness.
        mean_height_mm: float, mm, resulting volume-weighted mean physical layer height
            (target * delta' / delta).
        bounds: (L + 1,) float64, the slab boundaries (g_min ... g_max).
        anchors: (k,) float64, critical values inside the range made slab boundaries.
    """

    iso: np.ndarray
    delta: float
    delta_used: float
    mean_height_mm: float
    bounds: np.ndarray
    anchors: np.ndarray


def layer_spacing(g: np.ndarray, delta: float, layer_height_mm: float,
                  anchors: np.ndarray | None = None) -> LayerSpacing:
    """Iso-values for a field whose spacing ``delta`` gives mean height ``layer_height_mm``.

    Args:
        g: (V,) float64, field values.
        delta: float > 0, field units per target layer height (``FieldResult.delta``).
        layer_height_mm: float, mm, the target mean layer height.
        anchors: field values that must be slab boundaries (the critical regions' g); those
            within delta / 2 of the range's ends or of a lower anchor are dropped.

    Returns:
        The spacing (at least one layer).
    """
    g_min, g_max = float(np.min(g)), float(np.max(g))
    span = g_max - g_min
    if not np.isfinite(delta) or delta <= 0 or span <= 0:
        return LayerSpacing(np.array([g_min + 0.5 * span]), float(delta), span,
                            float("nan"), np.array([g_min, g_max]), np.zeros(0))
    knots = [g_min]
    for a in np.sort(np.asarray(anchors if anchors is not None else [], dtype=np.float64)):
        if a - knots[-1] >= 0.5 * delta and g_max - a >= 0.5 * delta:
            knots.append(float(a))
    knots.append(g_max)
    parts = [np.linspace(lo, hi, max(1, round((hi - lo) / delta)) + 1)[:-1]
             for lo, hi in itertools.pairwise(knots)]
    bounds = np.concatenate([*parts, [g_max]])
    iso = 0.5 * (bounds[1:] + bounds[:-1])
    used = span / len(iso)
    return LayerSpacing(iso, float(delta), used, layer_height_mm * used / delta, bounds,
                        np.asarray(knots[1:-1]))


def slab_bounds(iso: np.ndarray, g_min: float, g_max: float) -> np.ndarray:
    """(L + 1,) float64, the slab boundaries of iso-values that are slab middles.

    Rebuilt from g_min (b_{k+1} = 2 iso_k - b_k); iso-values that are not the middles of
    slabs tiling [g_min, g_max] (a hand-made ``Field``) get the midpoints between
    neighbours instead, the end slabs as thick as their neighbouring gap (a single layer:
    the whole range).
    """
    iso = np.asarray(iso, dtype=np.float64)
    b = np.empty(len(iso) + 1)
    b[0] = g_min
    for k, c in enumerate(iso):  # one step per layer
        b[k + 1] = 2.0 * c - b[k]
    span = max(g_max - g_min, tol.zero)
    if np.all(np.diff(b) > 0) and abs(b[-1] - g_max) <= tol.computed * span:
        b[-1] = g_max
        return b
    if len(iso) < 2:
        return np.array([min(g_min, float(iso[0])), max(g_max, float(iso[0]))])
    mid = 0.5 * (iso[1:] + iso[:-1])
    return np.concatenate([[1.5 * iso[0] - 0.5 * iso[1]], mid, [1.5 * iso[-1] - 0.5 * iso[-2]]])


def field_stage(result: FieldResult, layer_height_mm: float) -> tuple[Field, LayerSpacing]:
    """The ``field.npz`` stage of a field result, with its spacing (critical regions' g as
    slab boundaries)."""
    anchors = np.array([float(result.g[r.vertices[0]]) for r in result.regions.regions
                        if len(r.vertices)])
    spacing = layer_spacing(result.g, result.delta, layer_height_mm, anchors)
    return Field(g=result.g, iso=spacing.iso), spacing


def _case_table() -> np.ndarray:
    """(16, 2, 3) int64: for each above/below pattern, up to two triangles of local edges.

    Pattern bit k is set when tet vertex k is above the iso-value; -1 marks no triangle.
    """
    edge_of = {(int(a), int(b)): i for i, (a, b) in enumerate(TET_EDGES)}

    def e(a: int, b: int) -> int:
        return edge_of[(min(a, b), max(a, b))]

    table = np.full((16, 2, 3), -1, dtype=np.int64)
    for mask in range(16):  # 16 patterns, built once at import
        up = [k for k in range(4) if mask >> k & 1]
        down = [k for k in range(4) if not mask >> k & 1]
        if len(up) in (1, 3):
            apex, others = (up[0], down) if len(up) == 1 else (down[0], up)
            table[mask, 0] = [e(apex, o) for o in others]
        elif len(up) == 2:
            (a1, a2), (b1, b2) = up, down
            quad = [e(a1, b1), e(a1, b2), e(a2, b2), e(a2, b1)]
            table[mask, 0] = [quad[0], quad[1], quad[2]]
            table[mask, 1] = [quad[0], quad[2], quad[3]]
    return table


_CASES = _case_table()


class _Edges(NamedTuple):
    ends: np.ndarray  # (E, 2) int64 vertex indices of each unique edge
    of_tet: np.ndarray  # (T, 6) int64 unique-edge id of each local tet edge


def _unique_edges(tets: np.ndarray, n_vertices: int) -> _Edges:
    pairs = np.sort(tets[:, TET_EDGES].reshape(-1, 2), axis=1).astype(np.int64)
    key = pairs[:, 0] * np.int64(n_vertices) + pairs[:, 1]
    _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    return _Edges(ends=pairs[first], of_tet=inverse.reshape(-1, 6).astype(np.int64))


# A crossing this close (as a fraction of its edge) to an edge end is snapped onto that mesh
# vertex: crossings of several edges at one vertex become one layer vertex, and the
# near-zero-length edges and needle triangles they would form (which break the intrinsic
# Delaunay Laplacian of the toolpath stage) are never made.
SNAP_FRACTION = 1e-3


def _weld_crossings(
    edge_ids: np.ndarray, edges: _Edges, g: np.ndarray, x: np.ndarray, level: float,
    tet_of_tri: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Layer vertices of one iso-level: one per crossed tet edge, snapped to near mesh vertices.

    Args:
        edge_ids: (m, 3) int, crossed tet-edge ids of each triangle.
        edges: the mesh's unique edges.
        g: (V,) float64, the field; x: (V, 3) float64, mm, the tet vertices.
        level: the iso-value.
        tet_of_tri: (m,) int, tet of each triangle.

    Returns:
        faces (k, 3) int64 into verts (n, 3) float64 mm, and the tets (k,) of the kept faces;
        triangles collapsed by snapping are dropped.
    """
    used, inverse = np.unique(edge_ids, return_inverse=True)
    a, b = edges.ends[used, 0], edges.ends[used, 1]
    t = (level - g[a]) / (g[b] - g[a])
    # Key: the edge, or the mesh vertex the crossing snaps to (negative keys).
    key = used.astype(np.int64)
    at_a, at_b = t < SNAP_FRACTION, t > 1.0 - SNAP_FRACTION
    key = np.where(at_a, -1 - a, np.where(at_b, -1 - b, key))
    t = np.where(at_a, 0.0, np.where(at_b, 1.0, t))
    _, first, welded = np.unique(key, return_index=True, return_inverse=True)
    verts = x[a[first]] + t[first, None] * (x[b[first]] - x[a[first]])
    faces = welded[inverse.reshape(-1, 3)]
    f0, f1, f2 = faces.T
    keep = (f0 != f1) & (f1 != f2) & (f0 != f2)
    faces = faces[keep]
    if keep.all():
        return faces, verts, tet_of_tri
    # a vertex whose every triangle collapsed belongs to no face: drop it (it would get no
    # area-weighted gradient, hence no height or direction)
    kept, remap = np.unique(faces, return_inverse=True)
    return remap.reshape(-1, 3), verts[kept], tet_of_tri[keep]


def iso_surfaces(mesh: TetOperators | TetMesh, field: Field,
                 progress: Progress | None = None) -> Layers:
    """Marching-tetrahedra extraction of every iso-surface of ``field`` on a tet mesh.

    Args:
        mesh: the tet mesh the field lives on, or its operators (``FieldResult.operators``,
            saves rebuilding them).
        field: g (V,) and the increasing iso-values (L,).

    Returns:
        All layers in one ``Layers`` stage; layer k is the iso-surface ``g = iso[k]`` (all its
        connected components). vertex_height is t_k / |grad g| with t_k the thickness of
        layer k's slab (``slab_bounds``).
    """
    ops = mesh if isinstance(mesh, TetOperators) else build_operators(mesh)
    if len(field.g) != ops.n_vertices:
        raise InputError(f"the field has {len(field.g)} values for {ops.n_vertices} vertices",
                         "re-run the slicing stage on this tet mesh")
    g = np.asarray(field.g, dtype=np.float64)
    iso = np.asarray(field.iso, dtype=np.float64)
    x = ops.vertices
    tets = ops.tets
    gt = g[tets]
    tmin, tmax = gt.min(axis=1), gt.max(axis=1)
    by_min = np.argsort(tmin, kind="stable")
    sorted_min = tmin[by_min]
    edges = _unique_edges(tets, ops.n_vertices)
    grad = ops.gradient(g)
    span = float(g.max() - g.min()) if len(g) else 0.0
    if len(iso):
        thickness = np.diff(slab_bounds(iso, float(g.min()), float(g.max())))
    else:
        thickness = np.zeros(0)

    out_v: list[np.ndarray] = []
    out_f: list[np.ndarray] = []
    out_l: list[np.ndarray] = []
    out_h: list[np.ndarray] = []
    out_d: list[np.ndarray] = []
    offset = 0
    weights = np.array([1, 2, 4, 8])
    prog: Progress = progress if progress is not None else NullProgress()
    for k, level in enumerate(iso):  # one pass per layer; vectorised over tets inside
        if k % 16 == 0:
            prog.update(k / max(len(iso), 1), f"layer {k}/{len(iso)}")
        c = float(level)
        # Keep the iso-value off mesh vertices (a vertex exactly on it would give welded
        # duplicates of zero length).
        if np.any(np.abs(g - c) <= tol.iso * max(span, 1.0)):
            c += 2 * tol.iso * max(span, 1.0)
        head = by_min[: np.searchsorted(sorted_min, c, side="left")]
        cut = head[tmax[head] > c]
        if len(cut) == 0:
            continue
        mask = (gt[cut] > c) @ weights
        tri_local = _CASES[mask]  # (n, 2, 3)
        valid = tri_local[:, :, 0] >= 0
        tet_of_tri = np.broadcast_to(cut[:, None], valid.shape)[valid]
        local = tri_local[valid]  # (m, 3)
        edge_ids = np.take_along_axis(edges.of_tet[tet_of_tri], local, axis=1)
        faces, verts, tet_of_tri = _weld_crossings(edge_ids, edges, g, x, c, tet_of_tri)
        if len(faces) == 0:
            continue  # every triangle collapsed onto mesh vertices
        # Orient along the growth direction (the cut tet's gradient).
        p = verts[faces]
        normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        flip = np.einsum("ij,ij->i", normal, grad[tet_of_tri]) < 0
        faces[flip] = faces[flip][:, [0, 2, 1]]
        # Area weights, with a floor so a vertex touched only by sliver faces still gets the
        # mean gradient of its tets.
        area = 0.5 * np.linalg.norm(normal, axis=1)
        area = area + tol.floor * float(area.mean()) + tol.zero
        corner = faces.ravel()
        nv = len(verts)
        wsum = np.bincount(corner, weights=np.repeat(area, 3), minlength=nv)
        weighted = area[:, None] * grad[tet_of_tri]
        mean_grad = np.column_stack([
            np.bincount(corner, weights=np.repeat(weighted[:, i], 3), minlength=nv)
            for i in range(3)
        ]) / wsum[:, None]
        norm = np.linalg.norm(mean_grad, axis=1)
        direction = mean_grad / np.maximum(norm, tol.zero)[:, None]
        height = float(thickness[k]) / np.maximum(norm, tol.zero)
        out_v.append(verts)
        out_f.append(faces + offset)
        out_l.append(np.full(len(faces), k, dtype=np.int32))
        out_h.append(height)
        out_d.append(direction)
        offset += len(verts)

    if not out_v:
        empty = np.zeros((0, 3))
        return Layers(vertices=empty, faces=np.zeros((0, 3), dtype=np.int32),
                      face_layer=np.zeros(0, dtype=np.int32), vertex_height=np.zeros(0),
                      vertex_direction=empty)
    return Layers(
        vertices=np.concatenate(out_v),
        faces=np.concatenate(out_f),
        face_layer=np.concatenate(out_l),
        vertex_height=np.concatenate(out_h),
        vertex_direction=np.concatenate(out_d),
    )


def layer_gap(layers: Layers, index: int) -> tuple[np.ndarray, np.ndarray]:
    """Measured vs reported height for the vertices of layer ``index``.

    Args:
        layers: the extracted layers.
        index: a layer that has a next layer (index + 1 < layer_count).

    Returns:
        (measured (n,) float64 mm: distance from each vertex of layer ``index`` to the closest
        point of layer ``index + 1``; reported (n,) float64 mm: their ``vertex_height``).
    """
    import igl

    lower, upper = layers.layer(index), layers.layer(index + 1)
    sq, _, _ = igl.point_mesh_squared_distance(
        np.ascontiguousarray(lower.vertices), np.ascontiguousarray(upper.vertices),
        np.ascontiguousarray(upper.faces.astype(np.int64)))
    return np.sqrt(np.asarray(sq)), np.asarray(lower.height)


GAP_CHECK_PAIRS = 12  # layer pairs measured by the height check (evenly spread)


@dataclass(frozen=True, eq=False)
class LayerExtraction:
    """The layers stage and its checks.

    Attributes:
        field: the ``field.npz`` stage (g and iso-values).
        layers: the ``layers.npz`` stage.
        spacing: how the iso-values were chosen (delta', resulting mean height).
        critical_report: one JSON-ready dict per critical region: selector, kind ("start" or
            "end"), faces, vertices, area_mm2, g, slot (the region lies between iso[slot - 1]
            and iso[slot]), on_one_layer (all its vertices in that same slot),
            on_slab_boundary (g is a slab boundary: the region is a whole layer's face).
        height_check: JSON-ready dict comparing each vertex's reported height with the
            measured distance to the next layer: pairs, vertices, median_rel_error,
            p90_rel_error.
        height_scale: (L,) float64, the factor ``match_slab_heights`` applied to each
            layer's H (1 where it already matched its slab).
        slab_mm3: (len(iso),) float64, mm^3, the exact volume of each layer's slab.
    """

    field: Field
    layers: Layers
    spacing: LayerSpacing
    critical_report: list[dict[str, object]]
    height_check: dict[str, float]
    height_scale: np.ndarray
    slab_mm3: np.ndarray


def match_slab_heights(layers: Layers, ops: TetOperators, field: Field
                       ) -> tuple[Layers, np.ndarray, np.ndarray]:
    """``layers`` with H scaled per layer so that its integral over the layer is the exact
    volume of the layer's slab of the solid, the (L,) factors, and the exact slab volumes
    (len(iso),) mm^3 (``slicer.slabs``)."""
    n = layers.layer_count
    g = np.asarray(field.g, dtype=np.float64)
    iso = np.asarray(field.iso, dtype=np.float64)
    if len(iso) == 0:
        return layers, np.ones(n), np.zeros(0)
    bounds = slab_bounds(iso, float(g.min()), float(g.max()))
    slab = slab_volumes(ops.vertices, ops.tets, g, bounds)
    if n == 0 or len(layers.faces) == 0:
        return layers, np.ones(n), slab
    integral = height_integral(layers.vertices, layers.faces, layers.face_layer,
                               layers.vertex_height, n)
    scale = slab_height_scale(integral, slab[:n])
    vertex_layer = np.zeros(len(layers.vertices), dtype=np.int64)
    vertex_layer[layers.faces.ravel()] = np.repeat(layers.face_layer, 3)
    return Layers(
        vertices=layers.vertices,
        faces=layers.faces,
        face_layer=layers.face_layer,
        vertex_height=layers.vertex_height * scale[vertex_layer],
        vertex_direction=layers.vertex_direction,
    ), scale, slab


def check_heights(layers: Layers, pairs: int = GAP_CHECK_PAIRS) -> dict[str, float]:
    """Relative error |measured - reported| / reported of vertex heights on sample layers.

    Args:
        layers: the extracted layers.
        pairs: how many consecutive layer pairs to measure (evenly spread).

    Returns:
        {"pairs", "vertices", "median_rel_error", "p90_rel_error"} (NaN errors if fewer than
        two layers).
    """
    count = layers.layer_count
    if count < 2:
        nan = float("nan")
        return {"pairs": 0, "vertices": 0, "median_rel_error": nan, "p90_rel_error": nan}
    chosen = np.unique(np.linspace(0, count - 2, min(pairs, count - 1)).round().astype(int))
    errors = []
    for k in chosen:  # a few layer pairs
        measured, reported = layer_gap(layers, int(k))
        errors.append(np.abs(measured - reported) / np.maximum(reported, tol.zero))
    err = np.concatenate(errors)
    return {"pairs": len(chosen), "vertices": len(err),
            "median_rel_error": float(np.median(err)),
            "p90_rel_error": float(np.percentile(err, 90))}


def _critical_report(result: FieldResult, spacing: LayerSpacing) -> list[dict[str, object]]:
    out: list[dict[str, object]] = []
    iso, bounds = spacing.iso, spacing.bounds
    span = max(float(bounds[-1] - bounds[0]), tol.zero) if len(bounds) else 1.0
    for region in result.regions.regions:  # a handful of regions
        slots = np.unique(np.searchsorted(iso, result.g[region.vertices]))
        g_region = float(result.g[region.vertices[0]])
        out.append({
            "selector": region.selector,
            "kind": "end" if region.sign > 0 else "start",
            "faces": len(region.faces),
            "vertices": len(region.vertices),
            "area_mm2": region.area,
            "g": g_region,
            "slot": int(slots[0]),
            "on_one_layer": len(slots) == 1,
            # the region is the top (end) or bottom (start) face of a whole layer's slab
            "on_slab_boundary": bool(len(bounds) and
                                     np.min(np.abs(bounds - g_region)) <= tol.slack * span),
        })
    return out


def extract_layers(
    mesh: TetMesh | TetOperators,
    source: FieldResult | Field,
    config: SlicingConfig | None = None,
    progress: Progress | None = None,
) -> LayerExtraction:
    """The layers of a slicing field: iso-values, marching tets, and the checks.

    Args:
        mesh: the tet mesh (its operators are reused from ``source`` when it is a result).
        source: a field result (iso-values from its ``delta`` and the target height) or an
            existing ``Field`` stage (its iso-values are used as they are).
        config: slicing settings; its ``layer_height_mm`` overrides the result's target.
        progress: receives the stage start/end and per-layer progress.

    Returns:
        The extraction (field and layers stages, spacing, critical-region and height checks).
    """
    prog: Progress = progress if progress is not None else NullProgress()
    start = time.perf_counter()
    prog.start("layers")
    if isinstance(source, FieldResult):
        target = config.layer_height_mm if config is not None else source.layer_height_mm
        field, spacing = field_stage(source, target)
        ops = source.operators
        if len(source.g) != (len(mesh.vertices) if isinstance(mesh, TetMesh)
                             else mesh.n_vertices):
            raise InputError("the field result belongs to another tet mesh",
                             "re-run the slicing stage on this tet mesh")
        regions = _critical_report(source, spacing)
    else:
        field = source
        ops = mesh if isinstance(mesh, TetOperators) else build_operators(mesh)
        used = float(np.diff(field.iso).mean()) if len(field.iso) > 1 else float("nan")
        g = np.asarray(field.g, dtype=np.float64)
        bounds = (slab_bounds(field.iso, float(g.min()), float(g.max())) if len(field.iso)
                  else np.zeros(0))
        spacing = LayerSpacing(np.asarray(field.iso), float("nan"), used, float("nan"),
                               bounds, np.zeros(0))
        regions = []
    layers, scale, slab = match_slab_heights(iso_surfaces(ops, field, progress=prog), ops,
                                             field)
    check = check_heights(layers)
    prog.end("layers", time.perf_counter() - start)
    return LayerExtraction(field=field, layers=layers, spacing=spacing,
                           critical_report=regions, height_check=check, height_scale=scale,
                           slab_mm3=slab)
