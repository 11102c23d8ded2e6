"""Toolpath of the whole model: per layer component, width-constrained lines (paper 4.2, 4.3).

Layers are processed in parallel over chunks (``layer_build.layer_toolpath``: each layer's
components, ``strategy.component_toolpath``: how one component is printed), then
concatenated in increasing order, joined by travel moves lifted above the layer just
printed. Every waypoint carries H (interpolated from the face's vertices, raised to the
smallest height of the profile's table, where the speed saturates and W = C / (H v) would
diverge), the speed v = f(H / beta) and W = C / (H v); above the table H is kept, so W is
the spacing at which the slowest filament fills the slab. Travel waypoints copy H, v, W of
their neighbour (the planner chooses the travel speed). The normal of a surface waypoint is
the unit normal of the original layer there, oriented along growth (eq. 16; blended from
area-weighted vertex normals, ``mapback.point_normals``).

Limitation: travel clearance is measured against the current layer only (lifted above it);
printed material of earlier layers that rises above the straight traverse between two far
apart components of one layer is not detected (it would need the slicing field).
"""

from __future__ import annotations

import multiprocessing
import threading
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.path_accel import PathAccel
from core.progress import Progress
from core.stages import LayerMesh, Layers, Toolpath
from slicer.config import JobConfig, ToolpathConfig
from slicer.extrusion import ExtrusionProfile
from slicer.toolpath.layer_build import layer_pattern, layer_toolpath, split_layers
from slicer.toolpath.linking import Lifter
from slicer.toolpath.report import toolpath_report
from slicer.toolpath.results import (
    PATTERN_NAMES,
    LayerResult,
    ToolpathResult,
    Waypoints,
    travel_waypoints,
)
from slicer.toolpath.thin_features import thin_features

SERIAL_BELOW = 4  # fewer layers than this are processed in the calling process


def _run_chunk(args: tuple[list[LayerMesh], str, ToolpathConfig, ExtrusionProfile, bool,
                           PathAccel | None]) -> list[LayerResult]:
    meshes, first, cfg, profile, baselines, accel = args
    return [layer_toolpath(m, layer_pattern(m.index, first), cfg, profile, baselines, accel)
            for m in meshes if len(m.faces)]


def compute_toolpath(
    layers: Layers,
    config: JobConfig,
    profile: ExtrusionProfile,
    progress: Progress | None = None,
    measure_baselines: bool = True,
    workers: int = 2,
    accel: PathAccel | None = None,
) -> ToolpathResult:
    """Toolpath of all layers (module docstring) with its report section.

    Args:
        layers: the curved layers.
        config: the job config (``toolpath`` section used).
        profile: the extrusion profile.
        progress: receives ``update(fraction, detail)`` per finished chunk of layers.
        measure_baselines: also compute the width error without deformation and of the
            Poisson alternative on stripe layers (a third of the work on the socket).
        workers: processes; 1 (or few layers) runs in the calling process.
        accel: the path accelerations of the cell the job is for (None: the bundled cell's).
    """
    t_start = time.perf_counter()
    cfg = config.toolpath
    meshes = [m for m in split_layers(layers) if len(m.faces)]
    results: list[LayerResult] = []
    def report_progress(fraction: float, detail: str) -> None:
        if progress is not None:
            progress.update(fraction, detail)

    if workers <= 1 or len(meshes) < SERIAL_BELOW or multiprocessing.current_process().daemon:
        # (a daemonic process, e.g. a pipeline node, may not start worker processes)
        for i, m in enumerate(meshes):
            results.extend(_run_chunk(([m], cfg.first_pattern, cfg, profile, measure_baselines,
                                       accel)))
            report_progress((i + 1) / len(meshes), f"layer {m.index}")
    else:
        n_chunks = min(len(meshes), 4 * workers)
        chunks = [meshes[i::n_chunks] for i in range(n_chunks)]  # interleaved: balanced sizes
        done = 0
        # fork is cheap, but forking a process that runs other threads (a bus client) can
        # deadlock in the child: spawn then
        method = "fork" if threading.active_count() == 1 else "spawn"
        ctx = multiprocessing.get_context(method)
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
            futures = [pool.submit(_run_chunk, (c, cfg.first_pattern, cfg, profile,
                                                measure_baselines, accel)) for c in chunks]
            for fut in as_completed(futures):
                part = fut.result()
                results.extend(part)
                done += len(part)
                report_progress(done / len(meshes), f"{done}/{len(meshes)} layers")
    results.sort(key=lambda r: r.index)
    toolpath, stats = assemble(results)
    report, errors, status, timings = toolpath_report(results, toolpath, profile)
    # without them width_error_undeformed and width_error_poisson_stripe have n = 0
    report["baselines_measured"] = measure_baselines
    timings["total"] = time.perf_counter() - t_start
    report["timing_s"] = {k: round(v, 3) for k, v in timings.items()}
    report["per_layer"] = stats
    return ToolpathResult(toolpath, report, stats, errors, status, timings,
                          thin_features(results))


def assemble(results: list[LayerResult]) -> tuple[Toolpath, list[dict[str, Any]]]:
    """Concatenate layers in order with travel moves lifted above the layer just printed."""
    parts: list[Waypoints] = []
    layer_of: list[NDArray[np.int32]] = []
    stats: list[dict[str, Any]] = []
    prev: LayerResult | None = None
    for r in results:
        wp = r.waypoints
        if len(wp.position) == 0:
            continue
        if prev is not None:
            last = parts[-1]
            lifter = Lifter(prev.surface_vertices, prev.surface_normals)
            tp, tn = lifter.travel(last.position[-1], wp.position[0], prev.lift,
                                   2.0 * float(last.width[-1]))
            trav = travel_waypoints(tp, tn, last, -1)
            parts.append(trav)
            # the move finishes the layer just printed: it belongs to that layer
            layer_of.append(np.full(len(tp), prev.index, np.int32))
        parts.append(wp)
        layer_of.append(np.full(len(wp.position), r.index, np.int32))
        stats.append({
            "layer": r.index,
            "pattern": PATTERN_NAMES[r.pattern],
            "components": len(r.components),
            "waypoints": len(wp.position),
            "required_mm3": float(sum(c.required_mm3 for c in r.components)),
            "deposited_mm3": float(sum(c.deposited_mm3 for c in r.components)),
            "tau": [c.tau for c in r.components],
            "volume_status": [c.volume_status for c in r.components],
            "deform_status": [c.deform_status for c in r.components],
            "extrusion_starts": [c.extrusion_starts for c in r.components],
            "fallback": [c.fallback for c in r.components],
            "height_out_of_profile": r.height_out_of_profile,
        })
        prev = r
    allw = Waypoints.concat(parts)
    toolpath = Toolpath(
        position=allw.position,
        normal=allw.normal,
        layer=np.concatenate(layer_of) if layer_of else np.zeros(0, np.int32),
        path=allw.path,
        height=allw.height,
        width=allw.width,
        speed=allw.speed,
        extrude=allw.extrude,
        pattern=allw.pattern,
    )
    return toolpath, stats
