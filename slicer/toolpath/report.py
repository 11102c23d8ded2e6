"""The toolpath's report section: volumes, width errors per pattern (with the baselines),
extrusion starts, connector share, volume-match and deformation statuses, the profile."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.stages import Toolpath
from slicer.extrusion import ExtrusionProfile
from slicer.status import ComponentFallback, ToolpathStatus, VolumeStatus
from slicer.toolpath.linking import deposit_mask
from slicer.toolpath.results import PATTERN_NAMES, LayerResult
from slicer.toolpath.volume import segment_volume


def _pct(values: NDArray[np.float64]) -> dict[str, float | int]:
    """p50, p90, p95 and the count of ``values`` (NaN for none)."""
    if values.size == 0:
        return {"p50": float("nan"), "p90": float("nan"), "p95": float("nan"), "n": 0}
    p50, p90, p95 = np.percentile(values, [50, 90, 95])
    return {"p50": float(p50), "p90": float(p90), "p95": float(p95), "n": int(values.size)}


def _pct_range(values: NDArray[np.float64]) -> dict[str, float]:
    """min, p5, p50, p95, max of ``values`` (NaN for none)."""
    if values.size == 0:
        return {k: float("nan") for k in ("min", "p5", "p50", "p95", "max")}
    p5, p50, p95 = np.percentile(values, [5, 50, 95])
    return {"min": float(values.min()), "p5": float(p5), "p50": float(p50), "p95": float(p95),
            "max": float(values.max())}


def toolpath_report(results: list[LayerResult], tp: Toolpath, profile: ExtrusionProfile
                    ) -> tuple[dict[str, Any], dict[str, dict[str, NDArray[np.float64]]],
                               ToolpathStatus, dict[str, float]]:
    """The report section of ``results`` assembled into ``tp``, the width errors per pattern
    and kind, the status (``ToolpathStatus``: OK, VOLUME when a component missed the volume
    tolerance, FAILED_COMPONENTS when one was skipped) and the summed per-component timings."""
    comps = [c for r in results for c in r.components]
    errors: dict[str, dict[str, NDArray[np.float64]]] = {}
    for code, name in PATTERN_NAMES.items():
        sel = [c for c in comps if c.pattern == code]
        errors[name] = {
            "deformed": np.concatenate([c.width_error for c in sel]) if sel else np.zeros(0),
            "nominal": (np.concatenate([c.width_error_nominal for c in sel])
                        if sel else np.zeros(0)),
            "pointwise": (np.concatenate([c.width_error_pointwise for c in sel])
                          if sel else np.zeros(0)),
            "undeformed": (np.concatenate([c.width_error_undeformed for c in sel])
                           if sel else np.zeros(0)),
            "poisson": (np.concatenate([c.width_error_poisson for c in sel])
                        if sel else np.zeros(0)),
        }
    dep_mask = deposit_mask(tp.extrude, tp.path)
    seg = np.linalg.norm(np.diff(tp.position, axis=0), axis=1) if len(tp) > 1 else np.zeros(0)
    deposited = float(segment_volume(tp.position, tp.height, tp.width, dep_mask).sum())
    required = float(sum(c.required_mm3 for c in comps))
    ok_comps = [c for c in comps if not c.error]
    taus = np.array([c.tau for c in ok_comps])
    starts = [c.extrusion_starts for c in comps]
    statuses: dict[str, int] = {}
    for c in comps:
        statuses[c.volume_status] = statuses.get(c.volume_status, 0) + 1
    deform: dict[str, int] = {}
    for c in comps:
        key = c.deform_status.split(":")[0]
        deform[key] = deform.get(key, 0) + 1
    comp_err = np.array([c.deposited_mm3 / c.required_mm3 - 1 for c in ok_comps
                         if c.required_mm3 > 0])
    timings: dict[str, float] = {}
    for c in comps:
        for k, v in c.timings.items():
            timings[k] = timings.get(k, 0.0) + v
    n_vert = sum(r.n_vertices for r in results)
    out_of_range = sum(r.height_out_of_profile for r in results)
    report: dict[str, Any] = {
        "waypoints": len(tp),
        "paths": int(np.unique(tp.path[tp.extrude]).size),
        "travel_moves": int(np.unique(tp.path[~tp.extrude]).size),
        "length_mm": float(seg[dep_mask].sum()),
        "travel_length_mm": float(seg[~dep_mask].sum()),
        "deposited_volume_mm3": deposited,
        "required_volume_mm3": required,
        "layer_volume_error": deposited / required - 1.0 if required > 0 else float("nan"),
        "volume_error": None,  # deposited / model volume - 1: filled by the pipeline
        "width_error": {k: _pct(v["deformed"]) for k, v in errors.items()},
        # the same lines against the profile's W(H) rather than the width they print (they
        # differ where fit_flow scaled a component's speed)
        "width_error_nominal": {k: _pct(v["nominal"]) for k, v in errors.items()},
        # the same lines against the width at the point alone, not the mean of the two
        # neighbouring lines' (the measure up to session 13)
        "width_error_pointwise": {k: _pct(v["pointwise"]) for k, v in errors.items()},
        "width_error_undeformed": {k: _pct(v["undeformed"]) for k, v in errors.items()},
        "width_error_poisson_stripe": _pct(errors["stripe"]["poisson"]),
        # share of the measured points on lone lines (no other line within LONE_LINE x W:
        # a line filling a band about one width wide), measured by their band's width
        "width_error_no_neighbour_fraction": {
            name: (sum(c.width_lone_points for c in comps if c.pattern == code)
                   / errors[name]["deformed"].size if errors[name]["deformed"].size else 0.0)
            for code, name in PATTERN_NAMES.items()},
        "extrusion_starts": {
            "total": int(sum(starts)),
            "components": len(comps),
            "mean_per_component": float(np.mean(starts)) if starts else 0.0,
            "median_per_component": float(np.median(starts)) if starts else 0.0,
            "max_per_component": int(max(starts)) if starts else 0,
        },
        # share of the deposited volume laid by connectors between lines (counted in the
        # volume match; deposited over or beside neighbouring lines)
        "connector_volume_fraction": (float(sum(c.connector_mm3 for c in comps)) / deposited
                                      if deposited > 0 else 0.0),
        "tau": {"min": float(taus.min()) if taus.size else float("nan"),
                "max": float(taus.max()) if taus.size else float("nan")},
        "component_volume_error": {
            "max_abs": float(np.abs(comp_err).max()) if comp_err.size else 0.0,
            "p95_abs": float(np.percentile(np.abs(comp_err), 95)) if comp_err.size else 0.0,
        },
        "volume_match_status": statuses,
        "thin_fallback": {kind: sum(c.fallback == kind for c in comps)
                          for kind in (ComponentFallback.CONTOUR, ComponentFallback.CENTRE_LINE,
                                       ComponentFallback.TIP)},
        # contour components that are no band (fitted lines left holes, eq. 9 lines fill them)
        "band_fit_holes_filled": sum(c.fallback == ComponentFallback.HOLES_FILLED for c in comps),
        # no band, and eq. 9's contours alone kept their spacing better than the fitted ones
        "band_fit_dropped": sum(c.fallback == ComponentFallback.NO_BAND for c in comps),
        "deformation_status": deform,
        "height_out_of_profile_fraction": out_of_range / n_vert if n_vert else 0.0,
        "profile": {"name": profile.name, "sha256": profile.sha256,
                    "rate_mm3_s": profile.rate_mm3_s, "setpoint_mm3_s": profile.setpoint_mm3_s,
                    "beta": profile.beta, "calibrated": profile.calibrated,
                    "layer_height_range_mm": list(profile.layer_height_range)},
        "speed_mm_s": {"min": float(tp.speed.min()) if len(tp) else 0.0,
                       "max": float(tp.speed.max()) if len(tp) else 0.0},
        # the width printed over the profile's W(H) at extruding waypoints: what pitch_width,
        # the flow fit and first_layer_beta change (1 everywhere without them)
        "width_over_profile": _pct_range(tp.width[tp.extrude]
                                         / profile.width(tp.height[tp.extrude])),
    }
    failed = [f"layer {r.index}: {c.error}" for r in results for c in r.components if c.error]
    report["failed_components"] = {"count": len(failed), "reasons": failed[:20]}
    matched = set(statuses) <= {VolumeStatus.CONVERGED, VolumeStatus.CONVERGED_SCAN}
    status = ToolpathStatus.OK if matched else ToolpathStatus.VOLUME
    if failed:
        status = ToolpathStatus.FAILED_COMPONENTS
    return report, errors, status, timings
