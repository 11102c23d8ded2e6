"""How one layer component is printed: its width field, its surface, its lines, its report.

Per component: W per vertex from H (eq. 4); the component deformed to constant width (eqs.
13, 14) when W varies by more than DEFORM_SPREAD; contours or stripes on the deformed
surface at spacing tau * W_mean, tau by bisection until the deposited volume matches the
integral of H (``volume.match_volume``), chosen among alternatives by measuring
(``candidate_choice.py``); the chosen lines' width error against the width they print and,
on request, against baselines (the lines on the undeformed layer, Poisson stripes). A
component that cannot be processed becomes an empty result carrying its reason.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from core.path_accel import PathAccel
from core.stages import LayerMesh, Pattern
from core.tolerance import tol
from slicer.config import ToolpathConfig
from slicer.extrusion import ExtrusionProfile
from slicer.status import ComponentFallback, DeformStatus, VolumeStatus
from slicer.toolpath.candidate_choice import Candidates, choose
from slicer.toolpath.component import Component
from slicer.toolpath.deform import deform_to_constant_width
from slicer.toolpath.line_source import LineSource
from slicer.toolpath.linking import Lifter
from slicer.toolpath.results import ComponentResult, Waypoints
from slicer.toolpath.volume import required_volume

DEFORM_SPREAD = 0.01  # relative W spread above which the layer is deformed (eqs. 13, 14)

def component_toolpath(
    layer: LayerMesh, face_ids: NDArray[np.int64], pattern: int, cfg: ToolpathConfig,
    profile: ExtrusionProfile, start: NDArray[np.float64], lifter: Lifter, lift: float,
    measure_baselines: bool, accel: PathAccel | None = None,
) -> ComponentResult:
    """Toolpath of one component; a failure becomes an empty result carrying its reason.
    ``accel``: the job's cell's path accelerations (None: the bundled cell's)."""
    try:
        return _component_toolpath_unsafe(layer, face_ids, pattern, cfg, profile, start,
                                          lifter, lift, measure_baselines, accel)
    except (ValueError, RuntimeError, np.linalg.LinAlgError) as exc:
        faces = layer.faces[face_ids]
        required = required_volume(layer.vertices, faces, np.maximum(layer.height, 0.0))
        return ComponentResult(
            waypoints=Waypoints.concat([]), pattern=pattern, n_faces=len(faces),
            required_mm3=required, deposited_mm3=0.0, tau=float("nan"),
            volume_status=VolumeStatus.FAILED, volume_trace=(), deform_status=DeformStatus.FAILED,
            extrusion_starts=0, connector_mm3=0.0, width_error=np.zeros(0),
            width_error_undeformed=np.zeros(0),
            width_error_poisson=np.zeros(0), error=f"{type(exc).__name__}: {exc}",
        )


def _component_toolpath_unsafe(
    layer: LayerMesh, face_ids: NDArray[np.int64], pattern: int, cfg: ToolpathConfig,
    profile: ExtrusionProfile, start: NDArray[np.float64], lifter: Lifter, lift: float,
    measure_baselines: bool, accel: PathAccel | None = None,
) -> ComponentResult:
    """Toolpath of one connected layer component (see the module docstring)."""
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    comp = Component(layer, face_ids, pattern, cfg, profile, accel)
    spread = float((comp.width.max() - comp.width.min()) / max(comp.w_mean, tol.zero))
    deform_status: str = DeformStatus.SKIPPED
    deformed = comp.vertices
    if spread > DEFORM_SPREAD and cfg.deformation_iterations > 0:
        res = deform_to_constant_width(comp.vertices, comp.faces, comp.width,
                                       cfg.deformation_iterations,
                                       scale_tol=cfg.deformation_tolerance)
        deform_status = str(res.status)
        if np.all(np.isfinite(res.vertices)):
            deformed = np.asarray(res.vertices, dtype=np.float64)
        else:
            deform_status += ":not-finite(undeformed used)"
    timings["deform"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    perimeter = cfg.stripe_perimeter and pattern == Pattern.STRIPE
    surf = LineSource.of(deformed, comp.faces, cfg.fit_bands, perimeter, cfg.boundary_distance,
                         cfg.stripe_field, cfg.fit_ridge)
    surf.geometry.distance  # noqa: B018 (timed here: every line generator needs it)
    timings["distance"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    required = required_volume(comp.vertices, comp.faces, comp.height_sliced)
    cand = Candidates(comp, cfg, start, lifter, lift, required)
    chosen = choose(cand, surf, pattern, perimeter, deformed)
    match, used, fallback, surf = chosen.match, chosen.used, chosen.fallback, chosen.surface
    timings["lines"] = time.perf_counter() - t0
    built = match.result

    t0 = time.perf_counter()
    # against the width the waypoints carry (flow-fitted components print wider or
    # narrower lines on purpose), and against the profile's W(H) for comparison
    medial = (fallback == ComponentFallback.RIBS
              or (fallback == ComponentFallback.CENTRE_LINE and surf.geometry.loops != 2))
    measured = cand.measure(built.lines, built.flow, built.scale, medial)
    err_nominal = (measured.error if built.flow == 1.0 and built.scale is None
                   else cand.measure(built.lines, junctions=medial).error)
    err_undeformed = np.zeros(0)
    err_poisson = np.zeros(0)
    if measure_baselines:
        if deformed is comp.vertices or fallback == ComponentFallback.CENTRE_LINE:
            b = built  # no deformation (or one line): the direct lines are the lines
        else:
            banded = cfg.fit_bands and fallback != ComponentFallback.NO_BAND
            direct = replace(LineSource.of(comp.vertices, comp.faces, banded, perimeter,
                                           cfg.boundary_distance, cfg.stripe_field),
                             wall_half_width=surf.wall_half_width)
            if used == Pattern.CONTOUR:
                direct = direct.with_band_fit_holes_filled(comp.w_mean)
            b = cand.run(direct, used, match.tau).result
        # the baselines' lines would print at the same flow as the component's
        err_undeformed = cand.measure(b.lines, built.flow, b.scale).error
        if used == Pattern.STRIPE:
            pb = cand.run(surf, used, match.tau, poisson=True).result
            err_poisson = cand.measure(pb.lines, built.flow).error
    timings["baselines"] = time.perf_counter() - t0
    wp = replace(built.waypoints, pattern=np.full(len(built.waypoints.path), used, np.int8))
    return ComponentResult(
        waypoints=wp,
        pattern=used,
        n_faces=len(comp.faces),
        required_mm3=float(required),
        deposited_mm3=float(wp.deposited().sum()),
        tau=float(match.tau),
        volume_status=match.status,
        volume_trace=tuple((t.tau, t.volume, t.rel_error) for t in match.trace),
        deform_status=deform_status,
        extrusion_starts=built.linked.extrusion_starts,
        connector_mm3=float(wp.deposited()[built.linked.connector_segments()].sum()),
        width_error=measured.error,
        width_error_pointwise=measured.pointwise,
        width_error_nominal=err_nominal,
        width_lone_points=measured.lone,
        width_error_undeformed=err_undeformed,
        width_error_poisson=err_poisson,
        timings=timings,
        fallback=fallback,
    )
