"""How one layer component is printed: which lines, at which spacing, with which fallback.

Per component: W per vertex from H (eq. 4); the component deformed to constant width (eqs.
13, 14) when W varies by more than DEFORM_SPREAD; contours or stripes on the deformed
surface at spacing tau * W_mean, tau by bisection until the deposited volume matches the
integral of H (``volume.match_volume``). Choices made by measuring: a stripe component that
is mostly narrower than NARROW_STRIPES * W is printed with contours; a band at most about
one width wide holds one centre line whose width follows the band (between its two sides,
or its medial line where it has one boundary loop or many: ``medial.py``); a contour
component that is no band gets eq. 9's lines in the fitted lines' holes or eq. 9's alone,
lines fitted to its local width or eq. 9's rings (``ridge_fit.py``), and a stripe
component partly narrow walls gets the walls' centre lines, whichever keeps its spacing
better (p90 of the width error); a volume still off by THIN_SHORTFALL tries the other
pattern and the centre line; one off by FLOW_FIT_ABOVE gets its nozzle speed scaled. A
component that cannot be processed becomes an empty result carrying its reason.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from core.stages import LayerMesh, Pattern
from core.tolerance import tol
from slicer.config import ToolpathConfig
from slicer.extrusion import ExtrusionProfile
from slicer.status import FLOW_FITTED, ComponentFallback, DeformStatus, VolumeStatus
from slicer.toolpath.component import Built, Component
from slicer.toolpath.deform import deform_to_constant_width
from slicer.toolpath.line_source import LineSource
from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.linking import Lifter
from slicer.toolpath.results import ComponentResult, Waypoints
from slicer.toolpath.stripe_joins import coverage_miss
from slicer.toolpath.surface import boundary_edges
from slicer.toolpath.surface_geometry import CENTRE_WIDTH_SCALE
from slicer.toolpath.tip_line import tip_line
from slicer.toolpath.volume import VolumeMatch, match_volume, required_volume
from slicer.toolpath.width_measure import MeasuredWidth, measure_width

DEFORM_SPREAD = 0.01  # relative W spread above which the layer is deformed (eqs. 13, 14)
THIN_SHORTFALL = 0.25  # volume error beyond this after matching -> try the thin-band options
THIN_BAND = 0.6  # max boundary distance below this x W: a band for one line (centre line)
SHORT_JOIN = 2.0  # join limit (x W) retried where the configured one misses the volume
SHORT_JOIN_ABOVE = 0.01  # ... by more than this (relative)
THIN_BAND_FIT = 1.5  # fit_bands: widest band below this x W -> the one centre line
FLOW_FIT_ABOVE = 0.02  # ... where the spacing misses the component's volume by more
NARROW_STRIPES = 2.0  # a stripe-layer component narrower than this x W ...
NARROW_SHARE = 0.5  # ... over at least this share of its area gets contours
WALL_SHARE = 0.15  # ... over at least this share: its walls get their centre line

def component_toolpath(
    layer: LayerMesh, face_ids: NDArray[np.int64], pattern: int, cfg: ToolpathConfig,
    profile: ExtrusionProfile, start: NDArray[np.float64], lifter: Lifter, lift: float,
    measure_baselines: bool,
) -> ComponentResult:
    """Toolpath of one component; a failure becomes an empty result carrying its reason."""
    try:
        return _component_toolpath_unsafe(layer, face_ids, pattern, cfg, profile, start,
                                          lifter, lift, measure_baselines)
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
    measure_baselines: bool,
) -> ComponentResult:
    """Toolpath of one connected layer component (see the module docstring)."""
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    comp = Component(layer, face_ids, pattern, cfg, profile)
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

    def run(surface: LineSource, used: int, tau: float | None = None, poisson: bool = False,
            join: float | None = None, narrow: bool | None = None) -> VolumeMatch[Built]:
        """Lines of pattern ``used`` on ``surface``, volume-matched; with a fixed ``tau``
        only the lines (no linking: for the baseline width measurements)."""
        level_of = surface.contour_level() if used == Pattern.CONTOUR else None
        trim_of = surface.distance if used == Pattern.STRIPE else None

        def evaluate(t: float) -> tuple[float, Built]:
            spacing = t * comp.w_mean
            lines = surface.lines(used, spacing, poisson)
            scale = surface.width_scale(used, spacing) if cfg.pitch_width else None
            built = comp.build(lines, level_of, spacing, start, lifter, lift, trim_of,
                               link=tau is None, join=join, scale=scale, narrow=narrow)
            return float(built.waypoints.deposited().sum()), built

        if tau is not None:
            return match_volume(evaluate, required, cfg.volume_tolerance, tau, 1)
        return match_volume(evaluate, required, cfg.volume_tolerance)

    def flowed_width(width: NDArray[np.float64], speed: NDArray[np.float64], flow: float,
                     nominal: NDArray[np.float64]) -> NDArray[np.float64]:
        """W of those lines (W = C / (H v): W x v stays)."""
        return (width if flow == 1.0
                else width * speed / comp.flowed_speed(speed, flow, nominal))

    def fit_flow(built: Built) -> Built:
        """The nozzle speed scaled so the lines deposit the required volume (W = C / (H v)
        stays true; the filament gets thinner or fatter with it), within
        CENTRE_WIDTH_SCALE and the profile's speed table."""
        wp = built.waypoints
        volume = float(wp.deposited().sum())
        if volume <= 0 or required <= 0:
            return built
        flow = float(np.clip(required / volume, *CENTRE_WIDTH_SCALE))
        speed = comp.flowed_speed(wp.speed, flow, comp.profile.speed_at(wp.height))
        width = wp.width * wp.speed / speed
        return replace(built, waypoints=replace(wp, speed=speed, width=width),
                       flow=built.flow * flow)

    def centre_match(lines: SurfaceLines, scaled: bool = True) -> VolumeMatch[Built]:
        """One line along a band too narrow (or too wide) for W: its width is scaled to the
        band by the nozzle speed, point by point with ``pitch_width`` (``centre_scale``;
        not ``scaled``: no such band), then as a whole to the volume (``fit_flow``)."""
        scale = surf.centre_scale(comp.w_mean) if cfg.pitch_width and scaled else None
        # medial lines meet at junctions: a connector from one to the next would run along
        # a third, printing it twice; they are joined by travel moves
        join = None if surf.geometry.loops == 2 else 0.0

        def fixed_lines(t: float) -> tuple[float, Built]:
            built = fit_flow(comp.build(lines, None, comp.w_mean, start, lifter, lift,
                                        join=join, scale=scale))
            return float(built.waypoints.deposited().sum()), built

        return match_volume(fixed_lines, required, cfg.volume_tolerance, 1.0, 1)

    def boundary() -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        edges = boundary_edges(comp.faces)
        return comp.vertices[edges[:, 0]], comp.vertices[edges[:, 1]]

    def measure(lines: SurfaceLines, flow: float = 1.0,
                scale: NDArray[np.float64] | None = None,
                junctions: bool = False) -> MeasuredWidth:
        """Width error of ``lines`` against the width they print at ``flow`` (and the
        per-vertex width ``scale``); ``junctions``: medial lines meeting at junctions."""
        h_pt, v_pt, w_pt = comp.values_at(lines.face, lines.bary, scale)
        return measure_width(lines, flowed_width(w_pt, v_pt, flow, comp.profile.speed_at(h_pt)),
                             comp.normals[lines.face], boundary, junctions)

    def p90(m: VolumeMatch[Built]) -> float:
        """p90 of the measured width error of a candidate (inf where nothing could be
        measured: such a candidate never wins a comparison)."""
        err = measure(m.result.lines, m.result.flow, m.result.scale).error
        return float(np.percentile(err, 90)) if len(err) else float("inf")

    def mean_error(m: VolumeMatch[Built]) -> float:
        """Mean of the measured width error of a candidate (inf where nothing could be
        measured): unlike p90, it adds up over the components of a layer."""
        err = measure(m.result.lines, m.result.flow, m.result.scale).error
        return float(np.mean(err)) if len(err) else float("inf")

    def as_printed(m: VolumeMatch[Built]) -> VolumeMatch[Built]:
        """``m`` flow-fitted where its spacing misses the volume by more than
        FLOW_FIT_ABOVE, as it would be printed (its lines wider or narrower)."""
        return m if abs(m.rel_error) <= FLOW_FIT_ABOVE else replace(m, result=fit_flow(m.result))

    def run_joined(surface: LineSource, used: int) -> VolumeMatch[Built]:
        """``run``; where the match fails with the configured joins, also with short ones,
        keeping the better match."""
        match = run(surface, used)
        join: float | None = None
        if abs(match.rel_error) > SHORT_JOIN_ABOVE and cfg.join_factor > SHORT_JOIN:
            # Longer extruding joins make V(tau) jumpy (a join that flips adds or removes
            # a whole connector); where the match fails with them, e.g. on narrow bands
            # whose short lines make connectors a large share of the volume, link with
            # short joins only and keep whichever matches the volume better.
            short = run(surface, used, join=SHORT_JOIN)
            if abs(short.rel_error) < abs(match.rel_error):
                match, join = short, SHORT_JOIN
        if used == Pattern.STRIPE and cfg.narrow_joins and match.tau < 1.0:
            # Narrow joins leave their ink to the lines (``stripe_joins``); where the lines
            # then lie closer than their width (tau < 1: spots of the layer no stripe
            # reaches, e.g. between holes and the edge), joins at full width may place that
            # ink better: whichever leaves the smaller of the worse of gap and overlap
            full = run(surface, used, join=join, narrow=False)
            if (abs(full.rel_error) <= max(FLOW_FIT_ABOVE, abs(match.rel_error))
                    and coverage_miss(comp.vertices, comp.faces, full.result.waypoints)
                    < coverage_miss(comp.vertices, comp.faces, match.result.waypoints)):
                match = full
        return match

    used = pattern
    fallback: ComponentFallback = ComponentFallback.NONE
    if (pattern == Pattern.STRIPE
            and surf.geometry.mostly_narrow(0.5 * NARROW_STRIPES * comp.w_mean, NARROW_SHARE)):
        # stripes across a band this narrow are shorter than W once their ends are cut back
        # by W / 2: a zig-zag of stubs and connectors. A component that is mostly such a
        # band (a thin wall, a tube's shell, with or without a wider spot) is printed as on
        # a contour layer; there is no across-the-band direction to stagger anyway.
        used, fallback = Pattern.CONTOUR, ComponentFallback.CONTOUR
    # partly such walls (a junction between two tubes): also tried with stripes on the wide
    # part only and the walls' centre lines (``LineSource.narrow_walls``)
    geo = surf.geometry
    walls = (used == Pattern.STRIPE and cfg.fit_bands
             and geo.narrow_share(0.5 * NARROW_STRIPES * comp.w_mean, WALL_SHARE) >= WALL_SHARE
             and geo.sides is not None)
    # contours with fit_bands: a band narrower than 1.5 W everywhere holds round(b / W) = 1
    # line, the centre line, whose width is then fitted to the band (centre_match)
    thin = 0.5 * THIN_BAND_FIT if cfg.fit_bands and used == Pattern.CONTOUR else THIN_BAND
    centre = surf.centre_lines() if geo.max_distance < thin * comp.w_mean else None
    if centre is not None and centre.n_lines:
        # A band with holes at most about one width wide holds one line: along its middle.
        match, used, fallback = centre_match(centre), Pattern.CONTOUR, ComponentFallback.CENTRE_LINE
    else:
        if used == Pattern.CONTOUR:
            surf = surf.with_band_fit_holes_filled(comp.w_mean)
        no_band = used == Pattern.CONTOUR and surf.fill_holes
        if no_band:
            fallback = fallback or ComponentFallback.HOLES_FILLED
        match = run_joined(surf, used)
        if (used == Pattern.CONTOUR and surf.fit_ridge
                and (surf.band_sides() is None or surf.fill_holes)):
            # no band: the lines fitted to the local width (``ridge_fit.py``) at the pitch
            # of the lines laid where one is dropped for room, or at the blended pitch
            # where that spaces them better both in the tail and on average, as printed
            # (flow-fitted where the spacing misses the volume; p90 and mean:
            # a lower p90 alone can come with more lines a little off, which raises the
            # layer's p90; a plate with holes, whose families from the rim and the holes
            # meet in between, spaces them better blended) ...
            if surf.laid_pitch and surf.laid_pitch_matters(match.tau * comp.w_mean):
                blended = replace(surf, laid_pitch=False)
                alt = run_joined(blended, used)
                now, then = as_printed(match), as_printed(alt)
                if (abs(alt.rel_error) <= max(FLOW_FIT_ABOVE, abs(match.rel_error))
                        and p90(then) < p90(now) and mean_error(then) < mean_error(now)):
                    surf, match = blended, alt
            # ... or eq. 9's rings (in the band fit's holes), whichever keeps its spacing
            # better (p90)
            rings = replace(surf, fit_ridge=False)
            alt = run_joined(rings, used)
            if (abs(alt.rel_error) <= max(FLOW_FIT_ABOVE, abs(match.rel_error))
                    and p90(alt) < p90(match)):
                surf, match = rings, alt
        if no_band and abs(match.rel_error) <= FLOW_FIT_ABOVE:
            # No band: the fitted lines with eq. 9's in their holes, or eq. 9 alone (a
            # disc with slits at its rim, the membrane's dome top: p90 13 -> 12 %, p95
            # 44 -> 15 %; the aorta's plaque junctions keep the fitted lines, whose tail is
            # shorter there): the lines that keep their spacing better, p90 of the error
            plain = LineSource(surf.geometry, False, perimeter)
            alt = run_joined(plain, used)
            if abs(alt.rel_error) <= FLOW_FIT_ABOVE and p90(alt) < p90(match):
                surf, match, fallback = plain, alt, ComponentFallback.NO_BAND
        if walls:
            # kept where the lines keep their spacing better (the aorta's plaque junction:
            # stripe p90 34 -> 21 %; a plate with two holes, whose junction is short stubs
            # either way, keeps the stripes everywhere)
            walled = replace(surf, wall_half_width=0.5 * NARROW_STRIPES * comp.w_mean)
            alt = run_joined(walled, used)
            if (abs(alt.rel_error) <= max(FLOW_FIT_ABOVE, abs(match.rel_error))
                    and p90(alt) < p90(match)):
                surf, match, fallback = walled, alt, ComponentFallback.WALLS
    if abs(match.rel_error) > THIN_SHORTFALL and fallback != ComponentFallback.CENTRE_LINE:
        # A band about one width wide: stripes across it vanish once their ends are cut
        # back by W / 2, contours come out as a doubled loop. Try the other pattern and a
        # single line along the middle (bands with holes); keep the closest volume.
        options: list[tuple[VolumeMatch[Built], int, ComponentFallback]] = [
            (match, used, fallback)]
        if used == Pattern.STRIPE:
            options.append((run(surf, Pattern.CONTOUR), Pattern.CONTOUR, ComponentFallback.CONTOUR))
        centre = surf.centre_lines() if centre is None else centre
        if centre.n_lines:
            options.append((centre_match(centre), Pattern.CONTOUR, ComponentFallback.CENTRE_LINE))
        match, used, fallback = min(options, key=lambda o: abs(o[0].rel_error))
    if match.volume <= 0 and required > 0:
        # nothing printed: a tip or sliver smaller than any line of its pattern (a disc
        # about one width across) gets one line across it, its width fitted to the volume
        tip = tip_line(deformed, comp.faces, comp.w_mean)
        if tip.n_lines:
            match = centre_match(tip, scaled=False)
            used, fallback = Pattern.CONTOUR, ComponentFallback.TIP
    if (abs(match.rel_error) > FLOW_FIT_ABOVE
            and fallback not in (ComponentFallback.CENTRE_LINE, ComponentFallback.TIP)):
        # The line count is discrete (a band of 1.7 W holds 2 lines, not 1.7): where no
        # spacing matches the volume, the flow per length does.
        fitted = fit_flow(match.result)
        volume = float(fitted.waypoints.deposited().sum())
        match = replace(match, volume=volume, rel_error=volume / required - 1.0,
                        status=f"{match.status}{FLOW_FITTED}", result=fitted)
    timings["lines"] = time.perf_counter() - t0
    built = match.result

    t0 = time.perf_counter()
    # against the width the waypoints carry (flow-fitted components print wider or
    # narrower lines on purpose), and against the profile's W(H) for comparison
    medial = fallback == ComponentFallback.CENTRE_LINE and surf.geometry.loops != 2
    measured = measure(built.lines, built.flow, built.scale, medial)
    err_nominal = (measured.error if built.flow == 1.0 and built.scale is None
                   else measure(built.lines, junctions=medial).error)
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
            b = run(direct, used, match.tau).result
        # the baselines' lines would print at the same flow as the component's
        err_undeformed = measure(b.lines, built.flow, b.scale).error
        if used == Pattern.STRIPE:
            pb = run(surf, used, match.tau, poisson=True).result
            err_poisson = measure(pb.lines, built.flow).error
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
