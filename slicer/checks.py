"""What an operator should know about a sliced job, read from its ``report.json``.

Each note is one line naming the problem and, where there is one, the fix. ``mesp slice``
prints them; nothing here stops a job (a bad input raises ``InputError`` earlier).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from core.tolerance import tol
from slicer.toolpath.directions import JUMP_DEG
from slicer.toolpath.surface_geometry import CENTRE_WIDTH_SCALE

# Share of the layer vertices with H outside the profile above which the job is flagged.
HEIGHT_OUT_OF_PROFILE = 0.01
# |deposited / model volume - 1| above which the job is flagged (issue 3's 2 %).
VOLUME_ERROR = 0.02
# The narrowest line the toolpath prints, relative to the profile's W(H).
THINNEST = CENTRE_WIDTH_SCALE[0]
# Area share of a layer left bare or covered twice above which the job is flagged (issue 21).
COVERAGE_LIMIT = {"contour": 0.03, "stripe": 0.05}


def _downward_fix(report: Mapping[str, Any]) -> str:
    """The fix for downward printing directions, from the critical selectors used."""
    selectors = report.get("job", {}).get("config", {}).get("slicing", {}).get("critical", [])
    bottoms = [s for s in selectors if str(s).startswith("bottom")]
    if len(selectors) > 1 and bottoms:
        return (f"fix: keep only the bottom critical surface (--critical {bottoms[0]}): a second "
                "region the layers must also lie on folds them between the two")
    return ("fix: rotate the model so the part grows upward from its largest flat face, or "
            "name that face with --critical")


def _jump_note(direction: Mapping[str, Any], printability: Mapping[str, Any] | None) -> str:
    """The note on printing directions turning fast between neighbouring waypoints, with what
    the planner's bend test (``printability``, run at slicing time) found."""
    text = (f"toolpath: {direction['jumps']} neighbouring extruding waypoints turn their "
            f"printing direction by more than {JUMP_DEG:g} deg (up to "
            f"{direction['max_jump_deg']:.0f} deg; layers "
            f"{', '.join(map(str, direction['jump_layers']))}): the nozzle swings there")
    if printability is None:
        return text
    lo, hi = printability["alpha_range_deg"]
    if not printability.get("refused_waypoints"):
        return (f"{text}; the planner's bend test keeps alpha in [{lo:g}, {hi:g}] deg at "
                "every waypoint (the arm may slow there)")
    return f"{text}; the planner cannot follow some of them (see the plan note)"


def critical_line(report: Mapping[str, Any]) -> str | None:
    """One line naming the critical regions the slice used (selector, count, areas), or None
    before slicing."""
    regions = report.get("slicing", {}).get("critical_regions")
    if regions is None:
        return None
    if not regions:
        return "critical surfaces: none (the layers follow the part's height)"
    by_selector: dict[str, list[float]] = {}
    for r in regions:
        by_selector.setdefault(str(r["selector"]), []).append(float(r["area_mm2"]))
    parts = []
    for sel, areas in by_selector.items():
        shown = ", ".join(f"{a:.0f}" for a in areas[:4])
        more = f" +{len(areas) - 4} more" if len(areas) > 4 else ""
        parts.append(f"{sel}: {len(areas)} region(s) of {shown}{more} mm^2")
    return "critical surfaces: " + "; ".join(parts)


def job_notes(report: Mapping[str, Any]) -> list[str]:
    """One-line notes on a slice report: the model's repairs, the slicer's remarks (critical
    selectors that matched nothing or left patches out, solver fallbacks), layer heights
    the extrusion profile cannot print, skipped toolpath components, a volume mismatch."""
    notes = [f"model: {n}" for n in report.get("model", {}).get("repairs", [])]
    slicing = report.get("slicing", {})
    notes += [f"slicing: {n}" for n in slicing.get("notes", [])]
    toolpath = report.get("toolpath", {})
    if not toolpath:
        return notes
    share = float(toolpath.get("height_out_of_profile_fraction", 0.0))
    lo_hi = toolpath.get("profile", {}).get("layer_height_range_mm")
    if share > HEIGHT_OUT_OF_PROFILE and lo_hi:
        h = slicing.get("height_mm", {})
        notes.append(
            f"toolpath: {100 * share:.1f}% of the layer vertices have a layer height outside "
            f"the extrusion profile's {lo_hi[0]:.2f}-{lo_hi[1]:.2f} mm (layers span "
            f"{h.get('min', float('nan')):.2f}-{h.get('max', float('nan')):.2f} mm): their "
            "filaments are those of the nearest height it covers (spaced to give the slab "
            "its volume, but thicker or thinner than it, so the layers overlap less or "
            "more than beta says); fix: a layer height or critical surfaces that keep H in "
            "range (e.g. a position condition such as bottom:30@z<1), or a profile measured "
            "over a wider range (mesp calibrate)")
    failed = toolpath.get("failed_components", {})
    if failed.get("count", 0):
        reasons = "; ".join(failed.get("reasons", [])[:3])
        notes.append(f"toolpath: {failed['count']} layer component(s) skipped ({reasons}); "
                     "fix: a finer tet mesh (--edge-length) usually repairs degenerate layers")
    direction = toolpath.get("printing_direction", {})
    if direction.get("downward", 0):
        notes.append(
            f"toolpath: {direction['downward']} extruding waypoints print downward (up to "
            f"{direction['max_from_up_deg']:.0f} deg from up; layers "
            f"{', '.join(map(str, direction['downward_layers']))}): no cell can print them; "
            + _downward_fix(report))
    if direction.get("jumps", 0):
        notes.append(_jump_note(direction, report.get("printability")))
    refused = report.get("printability", {}).get("note")
    if refused:
        notes.append(f"plan: {refused}")
    for name in ("contour", "stripe"):
        cov = toolpath.get("coverage", {}).get(name, {})
        if cov.get("gap") is not None and (cov["gap"] > COVERAGE_LIMIT[name]
                                           or cov["overlap"] > COVERAGE_LIMIT[name]):
            notes.append(
                f"toolpath: {name} layers leave {100 * cov['gap']:.1f}% of their area bare and "
                f"cover {100 * cov['overlap']:.1f}% twice (limit "
                f"{100 * COVERAGE_LIMIT[name]:.0f}% each); see toolpath.coverage.per_layer")
    thin = toolpath.get("too_thin", {})
    thick = thin.get("excess_share", 0.0) > thin.get("limit", float("inf"))
    if thick:
        # printed anyway (thin_walls = "thicken"): the walls come out thicker than the model's
        layers = [k for k, _ in thin["layers"]]
        notes.append(
            f"toolpath: walls about {thin['wall_mm']:.2f} mm thick print at the narrowest line "
            f"({thin['line_mm']:.2f} mm) on {len(layers)} layer(s) ({layers[0]}-{layers[-1]}), "
            f"{100 * thin['excess_share']:+.1f}% of the model's volume in extra ink (see "
            f"toolpath.too_thin); fix: " + (
                f"--scale-to {thin['fits_at_size_mm']:.0f}, or a profile with a finer nozzle"
                if not thin.get("too_big") else
                f"a profile with a finer nozzle (at --scale-to {thin['fits_at_size_mm']:.0f}, "
                f"{thin['too_big']})"))
    error = toolpath.get("volume_error")
    if error is not None and abs(float(error)) > VOLUME_ERROR and not thick:
        narrowest = toolpath.get("width_over_profile", {}).get("min")
        if float(error) > 0 and narrowest is not None and narrowest <= THINNEST + tol.computed:
            # lines already at the narrowest width the nozzle speed can give, still too much
            # ink: the part has walls or features thinner than one filament
            notes.append(
                f"toolpath: deposited volume is {100 * float(error):+.1f}% off the model's: "
                "parts of it are thinner than the narrowest filament this profile prints "
                f"({THINNEST:g} x its W); fix: scale the model up (--scale-to MM, or the "
                "right --units) or use a profile with a finer nozzle")
        else:
            notes.append(f"toolpath: deposited volume is {100 * float(error):+.1f}% off the "
                         "model's (more than 2%); see toolpath.per_layer in report.json for "
                         "the layers")
    return notes
