"""One layer's toolpath: its pattern (staggered, Fig. 3d), its components in nearest-neighbour
order joined by travel moves lifted above the layer, and the layers as LayerMesh values."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from core.path_accel import PathAccel
from core.stages import LayerMesh, Layers, Pattern
from core.tolerance import tol
from slicer.config import ToolpathConfig
from slicer.extrusion import ExtrusionProfile
from slicer.toolpath.linking import LIFT_FACTOR, Lifter
from slicer.toolpath.pinholes import close_pinholes
from slicer.toolpath.results import ComponentResult, LayerResult, Waypoints, travel_waypoints
from slicer.toolpath.strategy import component_toolpath
from slicer.toolpath.surface import components


def layer_pattern(index: int, first: str) -> int:
    """Pattern of layer ``index``: ``first`` on even layers, the other on odd (Fig. 3d)."""
    first_code = Pattern.CONTOUR if first == "contour" else Pattern.STRIPE
    return first_code if index % 2 == 0 else 1 - first_code


def layer_toolpath(layer: LayerMesh, pattern: int, cfg: ToolpathConfig,
                   profile: ExtrusionProfile, measure_baselines: bool = True,
                   accel: PathAccel | None = None) -> LayerResult:
    """All components of one layer in nearest-neighbour order, joined by travel moves.
    Layer 0 uses ``cfg.first_layer_beta`` instead of the profile's beta when it is set.
    Holes far narrower than a line are closed first (``pinholes.py``).
    ``accel``: the job's cell's path accelerations (None: the bundled cell's)."""
    layer = close_pinholes(layer, profile)
    if layer.index == 0 and cfg.first_layer_beta > 0.0:
        profile = replace(profile, beta=cfg.first_layer_beta)

    lift = LIFT_FACTOR * float(layer.height.max()) if len(layer.height) else 0.0
    normals = layer.direction / np.maximum(
        np.linalg.norm(layer.direction, axis=1, keepdims=True), tol.zero
    )
    lifter = Lifter(layer.vertices, normals)
    comps = [np.asarray(c) for c in components(layer.faces)]
    # Deterministic layer start: the corner of the layer's bounding box.
    pos = layer.vertices.min(axis=0) if len(layer.vertices) else np.zeros(3)
    results: list[ComponentResult] = []
    parts: list[Waypoints] = []
    todo = list(range(len(comps)))
    while todo:
        dist = [float(np.min(np.linalg.norm(
            layer.vertices[np.unique(layer.faces[comps[i]])] - pos, axis=1))) for i in todo]
        ci = todo.pop(int(np.argmin(dist)))
        res = component_toolpath(layer, comps[ci], pattern, cfg, profile, pos, lifter, lift,
                                 measure_baselines, accel)
        wp = res.waypoints
        if len(wp.position) == 0:
            results.append(res)
            continue
        if parts:
            prev = parts[-1]
            tp, tn = lifter.travel(prev.position[-1], wp.position[0], lift,
                                   2.0 * float(prev.width[-1]))
            parts.append(travel_waypoints(tp, tn, prev, -1))
        parts.append(wp)
        results.append(res)
        pos = wp.position[-1]
    out_of_range = int(np.count_nonzero(~profile.in_range(layer.height)))
    return LayerResult(
        index=layer.index,
        pattern=pattern,
        waypoints=Waypoints.concat(parts),
        components=results,
        surface_vertices=layer.vertices,
        surface_normals=normals,
        lift=lift,
        height_out_of_profile=out_of_range,
        n_vertices=len(layer.vertices),
    )


def split_layers(layers: Layers) -> list[LayerMesh]:
    """All layers as LayerMesh, grouping faces by layer once (not one scan per layer)."""
    order = np.argsort(layers.face_layer, kind="stable")
    fl = layers.face_layer[order]
    out = []
    for i in range(layers.layer_count):
        lo, hi = np.searchsorted(fl, [i, i + 1])
        faces = layers.faces[order[lo:hi]]
        used, inverse = np.unique(faces, return_inverse=True)
        out.append(LayerMesh(
            index=i,
            vertices=layers.vertices[used],
            faces=inverse.reshape(-1, 3).astype(np.int32),
            height=layers.vertex_height[used],
            direction=layers.vertex_direction[used],
        ))
    return out
