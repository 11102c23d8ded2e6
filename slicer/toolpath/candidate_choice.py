"""Which lines print a layer component: alternatives built and the better one kept.

A component's lines can be laid several ways (its pattern's lines, volume-matched; one
centre line along a band about one width wide; contours fitted to the local width or eq.
9's rings; eq. 9 alone where the band fit leaves holes; stripes with the narrow walls'
centre lines; the other pattern or a line across a tip where the volume cannot be met).
``Candidates`` builds each alternative on the component and measures it (width error of its
lines, coverage of its joins); ``choose`` tries them in order and keeps whichever keeps its
spacing (p90, and the mean where lines are dropped) or its coverage better, then scales the
flow where no spacing matches the volume.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from core.stages import Pattern
from slicer.config import ToolpathConfig
from slicer.status import FLOW_FITTED, ComponentFallback
from slicer.toolpath.component import Built, Component
from slicer.toolpath.line_source import LineSource
from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.linking import Lifter
from slicer.toolpath.ribs import ribbed
from slicer.toolpath.stripe_joins import coverage_miss
from slicer.toolpath.surface import boundary_edges
from slicer.toolpath.surface_geometry import CENTRE_WIDTH_SCALE
from slicer.toolpath.tip_line import tip_line
from slicer.toolpath.volume import VolumeMatch, match_volume
from slicer.toolpath.width_measure import MeasuredWidth, measure_width

THIN_SHORTFALL = 0.25  # volume error beyond this after matching -> try the thin-band options
THIN_BAND = 0.6  # max boundary distance below this x W: a band for one line (centre line)
SHORT_JOIN = 2.0  # join limit (x W) retried where the configured one misses the volume
SHORT_JOIN_ABOVE = 0.01  # ... by more than this (relative)
THIN_BAND_FIT = 1.5  # fit_bands: widest band below this x W -> the one centre line
FLOW_FIT_ABOVE = 0.02  # ... where the spacing misses the component's volume by more
NARROW_STRIPES = 2.0  # a stripe-layer component narrower than this x W ...
NARROW_SHARE = 0.5  # ... over at least this share of its area gets contours
WALL_SHARE = 0.15  # ... over at least this share: its walls get their centre line


@dataclass(frozen=True)
class Choice:
    """The lines chosen for a component.

    Attributes:
        match: the volume match of the chosen lines (its ``result`` the built path).
        used: the pattern printed (``Pattern``), which a fallback may change.
        fallback: how the component was printed instead of its pattern, if it was.
        surface: the line source the chosen lines came from.
    """

    match: VolumeMatch[Built]
    used: int
    fallback: ComponentFallback
    surface: LineSource


@dataclass(frozen=True, eq=False)
class Candidates:
    """Builds and measures alternative lines on one component.

    Attributes:
        comp: the component (its own vertex numbering, H, W, speed, normals).
        cfg: the toolpath settings.
        start: (3,) float64 mm, where the path should start (the previous component's end).
        lifter: travel moves between extruding pieces.
        lift: mm, the travel lift.
        required: mm^3, the volume the component's lines must deposit (integral of H).
    """

    comp: Component
    cfg: ToolpathConfig
    start: NDArray[np.float64]
    lifter: Lifter
    lift: float
    required: float

    def run(self, surface: LineSource, used: int, tau: float | None = None,
            poisson: bool = False, join: float | None = None,
            narrow: bool | None = None) -> VolumeMatch[Built]:
        """Lines of pattern ``used`` on ``surface``, volume-matched; with a fixed ``tau``
        only the lines (no linking: for the baseline width measurements)."""
        comp, cfg = self.comp, self.cfg
        level_of = surface.contour_level() if used == Pattern.CONTOUR else None
        trim_of = surface.distance if used == Pattern.STRIPE else None

        def evaluate(t: float) -> tuple[float, Built]:
            spacing = t * comp.w_mean
            lines = surface.lines(used, spacing, poisson)
            scale = surface.width_scale(used, spacing) if cfg.pitch_width else None
            built = comp.build(lines, level_of, spacing, self.start, self.lifter, self.lift,
                               trim_of, link=tau is None, join=join, scale=scale, narrow=narrow)
            return float(built.waypoints.deposited().sum()), built

        if tau is not None:
            return match_volume(evaluate, self.required, cfg.volume_tolerance, tau, 1)
        return match_volume(evaluate, self.required, cfg.volume_tolerance)

    def fit_flow(self, built: Built) -> Built:
        """The nozzle speed scaled so the lines deposit the required volume (W = C / (H v)
        stays true; the filament gets thinner or fatter with it), within
        CENTRE_WIDTH_SCALE and the profile's speed table."""
        comp, wp = self.comp, built.waypoints
        volume = float(wp.deposited().sum())
        if volume <= 0 or self.required <= 0:
            return built
        flow = float(np.clip(self.required / volume, *CENTRE_WIDTH_SCALE))
        speed = comp.flowed_speed(wp.speed, flow, comp.profile.speed_at(wp.height))
        width = wp.width * wp.speed / speed
        return replace(built, waypoints=replace(wp, speed=speed, width=width),
                       flow=built.flow * flow)

    def centre_match(self, lines: SurfaceLines, surface: LineSource,
                     scaled: bool = True) -> VolumeMatch[Built]:
        """One line along a band too narrow (or too wide) for W: its width is scaled to the
        band by the nozzle speed, point by point with ``pitch_width`` (``centre_scale`` of
        ``surface``; not ``scaled``: no such band), then as a whole to the volume
        (``fit_flow``)."""
        comp = self.comp
        scale = (surface.centre_scale(comp.w_mean) if self.cfg.pitch_width and scaled
                 else None)
        # medial lines meet at junctions: a connector from one to the next would run along
        # a third, printing it twice; they are joined by travel moves
        join = None if surface.geometry.loops == 2 else 0.0

        def fixed_lines(t: float) -> tuple[float, Built]:
            built = self.fit_flow(comp.build(lines, None, comp.w_mean, self.start, self.lifter,
                                             self.lift, join=join, scale=scale))
            return float(built.waypoints.deposited().sum()), built

        return match_volume(fixed_lines, self.required, self.cfg.volume_tolerance, 1.0, 1)

    def _boundary(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The component's boundary edges: (m, 3) float64 mm start and end points."""
        edges = boundary_edges(self.comp.faces)
        return self.comp.vertices[edges[:, 0]], self.comp.vertices[edges[:, 1]]

    def measure(self, lines: SurfaceLines, flow: float = 1.0,
                scale: NDArray[np.float64] | None = None,
                junctions: bool = False) -> MeasuredWidth:
        """Width error of ``lines`` against the width they print at ``flow`` (and the
        per-vertex width ``scale``); ``junctions``: medial lines meeting at junctions."""
        comp = self.comp
        h_pt, v_pt, w_pt = comp.values_at(lines.face, lines.bary, scale)
        nominal = comp.profile.speed_at(h_pt)
        # W of those lines (W = C / (H v): W x v stays)
        width = w_pt if flow == 1.0 else w_pt * v_pt / comp.flowed_speed(v_pt, flow, nominal)
        return measure_width(lines, width, comp.normals[lines.face], self._boundary, junctions)

    def p90(self, m: VolumeMatch[Built], junctions: bool = False) -> float:
        """p90 of the measured width error of a candidate (inf where nothing could be
        measured: such a candidate never wins a comparison); ``junctions``: ``measure``'s."""
        err = self.measure(m.result.lines, m.result.flow, m.result.scale, junctions).error
        return float(np.percentile(err, 90)) if len(err) else float("inf")

    def mean_error(self, m: VolumeMatch[Built]) -> float:
        """Mean of the measured width error of a candidate (inf where nothing could be
        measured): unlike p90, it adds up over the components of a layer."""
        err = self.measure(m.result.lines, m.result.flow, m.result.scale).error
        return float(np.mean(err)) if len(err) else float("inf")

    def as_printed(self, m: VolumeMatch[Built]) -> VolumeMatch[Built]:
        """``m`` flow-fitted where its spacing misses the volume by more than
        FLOW_FIT_ABOVE, as it would be printed (its lines wider or narrower)."""
        return (m if abs(m.rel_error) <= FLOW_FIT_ABOVE
                else replace(m, result=self.fit_flow(m.result)))

    def run_joined(self, surface: LineSource, used: int) -> VolumeMatch[Built]:
        """``run``; where the match fails with the configured joins, also with short ones,
        keeping the better match."""
        cfg, comp = self.cfg, self.comp
        match = self.run(surface, used)
        join: float | None = None
        if abs(match.rel_error) > SHORT_JOIN_ABOVE and cfg.join_factor > SHORT_JOIN:
            # Longer extruding joins make V(tau) jumpy (a join that flips adds or removes
            # a whole connector, a large share of the volume on narrow bands): also link
            # with short joins only, keeping whichever matches the volume better.
            short = self.run(surface, used, join=SHORT_JOIN)
            if abs(short.rel_error) < abs(match.rel_error):
                match, join = short, SHORT_JOIN
        if used == Pattern.STRIPE and cfg.narrow_joins and match.tau < 1.0:
            # Narrow joins leave their ink to the lines (``stripe_joins``); where the lines
            # then lie closer than their width (tau < 1: spots of the layer no stripe
            # reaches, e.g. between holes and the edge), joins at full width may place that
            # ink better: whichever leaves the smaller of the worse of gap and overlap
            full = self.run(surface, used, join=join, narrow=False)
            if (abs(full.rel_error) <= max(FLOW_FIT_ABOVE, abs(match.rel_error))
                    and coverage_miss(comp.vertices, comp.faces, full.result.waypoints)
                    < coverage_miss(comp.vertices, comp.faces, match.result.waypoints)):
                match = full
        return match


def choose(cand: Candidates, surf: LineSource, pattern: int, perimeter: bool,
           deformed: NDArray[np.float64]) -> Choice:
    """The lines of one component: its pattern's, or the alternative that keeps its spacing
    better (see the module docstring); ``deformed``: (n, 3) float64 mm, the component's
    vertices deformed to constant width, where a tip's line is laid."""
    comp, cfg = cand.comp, cand.cfg
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
        match, used, fallback = (cand.centre_match(centre, surf), Pattern.CONTOUR,
                                 ComponentFallback.CENTRE_LINE)
    else:
        if used == Pattern.CONTOUR:
            surf = surf.with_band_fit_holes_filled(comp.w_mean)
        no_band = used == Pattern.CONTOUR and surf.fill_holes
        if no_band:
            fallback = fallback or ComponentFallback.HOLES_FILLED
        match = cand.run_joined(surf, used)
        if (used == Pattern.CONTOUR and surf.fit_ridge
                and (surf.band_sides() is None or surf.fill_holes)):
            # no band: the lines fitted to the local width (``ridge_fit.py``) at the pitch
            # of the lines laid where one is dropped for room, or at the blended pitch
            # where that spaces them better in the tail and on average, as printed (a
            # lower p90 alone can come with more lines a little off, which raises the
            # layer's p90) ...
            if surf.laid_pitch and surf.laid_pitch_matters(match.tau * comp.w_mean):
                blended = replace(surf, laid_pitch=False)
                alt = cand.run_joined(blended, used)
                now, then = cand.as_printed(match), cand.as_printed(alt)
                if (abs(alt.rel_error) <= max(FLOW_FIT_ABOVE, abs(match.rel_error))
                        and cand.p90(then) < cand.p90(now)
                        and cand.mean_error(then) < cand.mean_error(now)):
                    surf, match = blended, alt
            # ... or eq. 9's rings (in the band fit's holes), whichever keeps its spacing
            # better (p90)
            rings = replace(surf, fit_ridge=False)
            alt = cand.run_joined(rings, used)
            if (abs(alt.rel_error) <= max(FLOW_FIT_ABOVE, abs(match.rel_error))
                    and cand.p90(alt) < cand.p90(match)):
                surf, match = rings, alt
        if no_band and abs(match.rel_error) <= FLOW_FIT_ABOVE:
            # No band: the fitted lines with eq. 9's in their holes, or eq. 9 alone (a
            # disc with slits at its rim, the membrane's dome top), whichever keeps its
            # spacing better (p90 of the error)
            plain = LineSource(surf.geometry, False, perimeter)
            alt = cand.run_joined(plain, used)
            if abs(alt.rel_error) <= FLOW_FIT_ABOVE and cand.p90(alt) < cand.p90(match):
                surf, match, fallback = plain, alt, ComponentFallback.NO_BAND
        if walls:
            # stripes on the wide part and the walls' centre lines, kept where the lines
            # keep their spacing better (p90)
            walled = replace(surf, wall_half_width=0.5 * NARROW_STRIPES * comp.w_mean)
            alt = cand.run_joined(walled, used)
            if (abs(alt.rel_error) <= max(FLOW_FIT_ABOVE, abs(match.rel_error))
                    and cand.p90(alt) < cand.p90(match)):
                surf, match, fallback = walled, alt, ComponentFallback.WALLS
        ribs = ribbed(cand, surf, match, used, 0.5 * THIN_BAND_FIT, WALL_SHARE, FLOW_FIT_ABOVE)
        if ribs is not None:  # walls too narrow for two lines beside a wider part (ribs.py)
            (surf, match), fallback = ribs, ComponentFallback.RIBS
    if abs(match.rel_error) > THIN_SHORTFALL and fallback != ComponentFallback.CENTRE_LINE:
        # A band about one width wide (stripes vanish once cut back by W / 2, contours
        # double): the other pattern and one middle line tried; the closest volume kept.
        options: list[tuple[VolumeMatch[Built], int, ComponentFallback]] = [
            (match, used, fallback)]
        if used == Pattern.STRIPE:
            options.append((cand.run(surf, Pattern.CONTOUR), Pattern.CONTOUR,
                            ComponentFallback.CONTOUR))
        centre = surf.centre_lines() if centre is None else centre
        if centre.n_lines:
            options.append((cand.centre_match(centre, surf), Pattern.CONTOUR,
                            ComponentFallback.CENTRE_LINE))
        match, used, fallback = min(options, key=lambda o: abs(o[0].rel_error))
    if match.volume <= 0 and cand.required > 0:
        # nothing printed: a tip or sliver smaller than any line of its pattern (a disc
        # about one width across) gets one line across it, its width fitted to the volume
        tip = tip_line(deformed, comp.faces, comp.w_mean)
        if tip.n_lines:
            match = cand.centre_match(tip, surf, scaled=False)
            used, fallback = Pattern.CONTOUR, ComponentFallback.TIP
    if (abs(match.rel_error) > FLOW_FIT_ABOVE
            and fallback not in (ComponentFallback.CENTRE_LINE, ComponentFallback.TIP)):
        # The line count is discrete (a band of 1.7 W holds 2 lines, not 1.7): where no
        # spacing matches the volume, the flow per length does.
        fitted = cand.fit_flow(match.result)
        volume = float(fitted.waypoints.deposited().sum())
        match = replace(match, volume=volume, rel_error=volume / cand.required - 1.0,
                        status=f"{match.status}{FLOW_FITTED}", result=fitted)
    return Choice(match, used, fallback, surf)
