"""Toolpath of the whole model: per layer component, width-constrained lines (paper 4.2, 4.3).

Per layer (in parallel over chunks of layers):
  pattern = first_pattern on even layers, the other one on odd layers (staggering, Fig. 3d);
  per connected component of the layer:
    W per vertex from H through the extrusion profile (eq. 4);
    deform the component to constant width (eqs. 13, 14) when W varies by more than 1 %;
    on the deformed surface: boundary distance, then contours or stripes (eqs. 10-12)
      at spacing tau * W_mean, mapped back to the original layer (eqs. 15, 16), short
      fragments dropped, resampled at waypoint_spacing * W, ordered, linked;
      contours: eq. 9 on a component with one boundary loop (disc-like); on a band between
      two or more loops (fit_bands) a whole number of lines across the local band width
      (contours.two_sided_contour_lines), printed from the outer wall inwards;
    tau by bisection until the deposited volume matches the integral of H (volume.py).
  components in nearest-neighbour order, joined by lifted travel moves.
Layers are concatenated in increasing order, joined by travel moves lifted above the layer
just printed. Every waypoint carries H (interpolated from the face's vertices), the speed
v = f(H / beta) and W = C / (H v), with H raised to the smallest height of the profile's table
(below it the speed saturates and W = C / (H v) would diverge as H -> 0; the raised H is the
one stored, so eq. 4 holds per waypoint). Above the table H is kept: the speed saturates at
the slowest and W = C / (H v) is the spacing at which that filament fills the slab (on the
bundled membrane, whose dome layers reach H 3 mm, clamping H there as well gave W 8 mm where
the lines must lie 4.4 mm apart, and contour width error p90 16.8 % instead of 12.8 %);
travel waypoints copy H, v, W of their neighbour (the planner
chooses the travel speed). The normal of a surface waypoint is the unit normal of the
original layer there, oriented along growth (eq. 16; blended from area-weighted vertex
normals so that sliver faces do not give normal spikes, mapback.point_normals). Open stripe
lines that end on the boundary are cut back by W / 2 (at most a quarter of their length per
end) so their band of material ends at the boundary. On stripe layers with
``stripe_perimeter`` one loop at spacing / 2 inside the boundary is added, printed first,
and the stripes are clipped PERIMETER_CLIP spacings inside the boundary (perimeter.py; only
on components wider than PERIMETER_MIN_DISTANCE spacings from the boundary); the loop is part
of the volume match. Thin components: a band with holes
whose largest boundary distance is below THIN_BAND * W holds one line, printed along its
middle (iso-line 1/2 of a harmonic function that is 0 on the outer and 1 on the inner
boundary loops), its width scaled to the band's volume by the speed (within
CENTRE_WIDTH_SCALE and the profile's table: a thin wall gets a thinner, faster line instead of
a 1.5x overfill); when the volume of the regular pattern stays off by more than
THIN_SHORTFALL, the other pattern and that centre line are tried and the closest volume wins
(reported as 'thin_fallback'). Two more choices are made by measuring (the p90 of the
width error of both candidates): a contour component that is no band (the fitted lines
leave holes) is printed with eq. 9's lines in those holes or with eq. 9's lines alone
('no-band'); a stripe component that is partly walls narrower than NARROW_STRIPES * W
(WALL_SHARE of its area or more) with stripes everywhere or with the walls' centre lines
and stripes on the wide part only ('walls'). A component that cannot be
processed (no boundary, a solver failure) is skipped with its reason in the report instead
of stopping the whole job.

Limitation: travel clearance is measured against the current layer only (lifted above it);
printed material of earlier layers that rises above the straight traverse between two far
apart components of one layer is not detected (it would need the slicing field).
"""

from __future__ import annotations

import multiprocessing
import threading
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field, replace
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from core.progress import Progress
from core.stages import LayerMesh, Layers, Pattern, Toolpath
from core.tolerance import tol
from slicer.config import JobConfig, ToolpathConfig
from slicer.extrusion import ExtrusionProfile
from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.linking import (
    LIFT_FACTOR,
    Joiner,
    Lifter,
    LinkedPath,
    deposit_mask,
    link_pieces,
    mesh_graph,
)
from slicer.toolpath.mapback import (
    face_normals,
    interpolate,
    map_back,
    point_normals,
    vertex_normals,
)
from slicer.toolpath.ordering import line_levels, order_lines
from slicer.toolpath.peaks import add_distance_peaks
from slicer.toolpath.resample import (
    drop_short_lines,
    drop_tiny_loops,
    face_neighbours,
    line_index,
    line_lengths,
    resample_lines,
)
from slicer.toolpath.volume import (
    VolumeMatch,
    match_volume,
    required_volume,
    segment_volume,
)

PATTERN_NAMES: dict[int, str] = {Pattern.CONTOUR: "contour", Pattern.STRIPE: "stripe"}
DEFORM_SPREAD = 0.01  # relative W spread above which the layer is deformed (eqs. 13, 14)
SERIAL_BELOW = 4  # fewer layers than this are processed in the calling process
THIN_SHORTFALL = 0.25  # volume error beyond this after matching -> try the thin-band options
THIN_BAND = 0.6  # max boundary distance below this x W: a band for one line (centre line)
SHORT_JOIN = 2.0  # join limit (x W) retried where the configured one misses the volume
SHORT_JOIN_ABOVE = 0.01  # ... by more than this (relative)
THIN_BAND_FIT = 1.5  # fit_bands: widest band below this x W -> the one centre line
PITCH_SMOOTHING = 2.0  # contour pitch blended over this x W where the line count changes
CENTRE_WIDTH_SCALE = (0.5, 1.5)  # a line's width may be scaled by the nozzle speed this far
FLOW_FIT_ABOVE = 0.02  # ... where the spacing misses the component's volume by more
TINY_LOOP = 2.0  # closed lines shorter than this x W are dropped (a blob, not a loop)
NARROW_STRIPES = 2.0  # a stripe-layer component narrower than this x W ...
NARROW_SHARE = 0.5  # ... over at least this share of its area gets contours
WALL_SHARE = 0.15  # ... over at least this share: its walls get their centre line
UNCOVERED = 0.8  # band fitting fails where an area is farther than this x spacing from lines
UNCOVERED_SHARE = 0.02  # ... more than this share of the component (eq. 9 lines fill them)
LONE_LINE = 2.0  # no other line within this x W: the line fills its band alone (_measure)


def layer_pattern(index: int, first: str) -> int:
    """Pattern of layer ``index``: ``first`` on even layers, the other on odd (Fig. 3d)."""
    first_code = Pattern.CONTOUR if first == "contour" else Pattern.STRIPE
    return first_code if index % 2 == 0 else 1 - first_code


@dataclass(frozen=True, eq=False)
class Waypoints:
    """Waypoints in print order with their process values (one layer or component).

    Attributes:
        position: (N, 3) float64, mm.
        normal: (N, 3) float64, unit.
        height: (N,) float64, mm.
        width: (N,) float64, mm.
        speed: (N,) float64, mm/s.
        extrude: (N,) bool.
        path: (N,) int32, local path id, increasing in print order.
        pattern: (N,) int8, 0 contour, 1 stripe (the pattern the waypoint belongs to).
    """

    position: NDArray[np.float64]
    normal: NDArray[np.float64]
    height: NDArray[np.float64]
    width: NDArray[np.float64]
    speed: NDArray[np.float64]
    extrude: NDArray[np.bool_]
    path: NDArray[np.int32]
    pattern: NDArray[np.int8]

    @staticmethod
    def concat(parts: list[Waypoints]) -> Waypoints:
        """Concatenate, shifting each part's path ids past the previous ones."""
        if not parts:
            return Waypoints(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0),
                             np.zeros(0), np.zeros(0, bool), np.zeros(0, np.int32),
                             np.zeros(0, np.int8))
        offs, paths = 0, []
        for p in parts:
            paths.append(p.path + offs)
            offs += int(p.path.max()) + 1 if len(p.path) else 0
        return Waypoints(
            position=np.concatenate([p.position for p in parts]),
            normal=np.concatenate([p.normal for p in parts]),
            height=np.concatenate([p.height for p in parts]),
            width=np.concatenate([p.width for p in parts]),
            speed=np.concatenate([p.speed for p in parts]),
            extrude=np.concatenate([p.extrude for p in parts]),
            path=np.concatenate(paths).astype(np.int32),
            pattern=np.concatenate([p.pattern for p in parts]).astype(np.int8),
        )

    def deposited(self) -> NDArray[np.float64]:
        """(N - 1,) float64, mm^3, volume of each segment (eq. 2)."""
        return segment_volume(self.position, self.height, self.width,
                              deposit_mask(self.extrude, self.path))


@dataclass(frozen=True, eq=False)
class ComponentResult:
    """One layer component's toolpath and its measurements.

    Attributes:
        waypoints: the component's waypoints (surface and travel).
        pattern: 0 contour, 1 stripe: the pattern used (a stripe layer's component too
            narrow for stripes falls back to contours).
        n_faces: faces of the component.
        required_mm3: integral of H over the component.
        deposited_mm3: deposited volume of the waypoints.
        tau: chosen spacing factor.
        volume_status: status of the bisection; volume_trace: (tau, volume, rel_error) rows.
        deform_status: status of the width deformation ('skipped' when W is constant).
        extrusion_starts: continuous extrusion paths in the component.
        connector_mm3: deposited volume of the connectors that join lines (included in
            deposited_mm3, so the volume match accounts for it).
        width_error: (k,) float64, |spacing - W| / W at the line points (deformed method),
            W the width the waypoints print (after ``fit_flow``, if it scaled the speed),
            the mean of the point's and the neighbouring line's (``_measure``).
        width_error_pointwise: (k,) float64, the same against the point's W alone.
        width_error_nominal: (k,) float64, the same against the profile's W(H).
        width_lone_points: how many of those are on lone lines, measured by their band.
        width_error_undeformed: (k',) float64, same, lines computed on the original layer.
        width_error_poisson: (k'',) float64, Poisson alternative (stripe layers), else empty.
        timings: stage -> s.
        error: why the component was skipped ('' if it was not).
        fallback: '' or how a component too narrow for its pattern was printed instead
            ('contour' on a stripe layer, 'centre-line': one line along the band's middle),
            or 'holes-filled': fitted contours left holes (the component is no band),
            filled with eq. 9's iso-lines.
    """

    waypoints: Waypoints
    pattern: int
    n_faces: int
    required_mm3: float
    deposited_mm3: float
    tau: float
    volume_status: str
    volume_trace: tuple[tuple[float, float, float], ...]
    deform_status: str
    extrusion_starts: int
    connector_mm3: float
    width_error: NDArray[np.float64]
    width_error_undeformed: NDArray[np.float64]
    width_error_poisson: NDArray[np.float64]
    width_error_nominal: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    width_error_pointwise: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    width_lone_points: int = 0
    timings: dict[str, float] = field(default_factory=dict)
    error: str = ""
    fallback: str = ""


@dataclass(frozen=True, eq=False)
class LayerResult:
    """One layer's toolpath.

    Attributes:
        index: layer index.
        pattern: 0 contour, 1 stripe.
        waypoints: all components, joined by travel moves.
        components: per-component results (print order).
        surface_vertices: (n, 3) float64, mm, layer vertices (for travel clearance).
        surface_normals: (n, 3) float64, unit growth direction per vertex.
        lift: float, mm, travel clearance above this layer.
        height_out_of_profile: int, vertices whose H lies outside the profile's table.
        n_vertices: int, vertices of the layer.
    """

    index: int
    pattern: int
    waypoints: Waypoints
    components: list[ComponentResult]
    surface_vertices: NDArray[np.float64]
    surface_normals: NDArray[np.float64]
    lift: float
    height_out_of_profile: int
    n_vertices: int


@dataclass(frozen=True, eq=False)
class ToolpathResult:
    """Output of ``compute_toolpath``.

    Attributes:
        toolpath: the Toolpath stage.
        report: the design.md "toolpath" report section (+ extra keys).
        layer_stats: per-layer dicts (layer, pattern, components, volumes, tau, starts).
        width_errors: {"contour"|"stripe": {"deformed"|"undeformed"|"poisson": (k,) f8}}.
        status: 'ok'; 'volume' when some component missed the volume tolerance;
            'failed-components' when some component was skipped (reasons in the report).
        timings: stage -> s (summed over layers for per-layer stages).
    """

    toolpath: Toolpath
    report: dict[str, Any]
    layer_stats: list[dict[str, Any]]
    width_errors: dict[str, dict[str, NDArray[np.float64]]]
    status: str
    timings: dict[str, float]


def _compact(vertices: NDArray[np.float64], faces: NDArray[np.int32]) -> tuple[
    NDArray[np.integer], NDArray[np.int32]
]:
    used, inverse = np.unique(faces, return_inverse=True)
    return used, inverse.reshape(-1, 3).astype(np.int32)


def _mean_width(vertices: NDArray[np.float64], faces: NDArray[np.int32],
                width: NDArray[np.float64]) -> float:
    """Area-weighted mean of W over the surface (W-bar of eq. 14)."""
    tri = vertices[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    total = float(area.sum())
    if total <= tol.zero:
        return float(width.mean())
    return float((area * width[faces].mean(axis=1)).sum() / total)


class _Surface:
    """What the line generators need of one (possibly deformed) component surface."""

    def __init__(self, vertices: NDArray[np.float64], faces: NDArray[np.int32],
                 fit_bands: bool = True, perimeter: bool = False,
                 distance: Literal["eikonal", "heat"] = "eikonal") -> None:
        from slicer.toolpath.geodesic import boundary_distance

        self.vertices = vertices
        self.faces = faces
        self.backend: Literal["eikonal", "heat"] = distance
        # contours, stripe directions, trims, perimeters (geodesic.py, eikonal.py)
        self.distance = boundary_distance(vertices, faces, backend=distance)
        self.max_distance = float(self.distance.max()) if len(self.distance) else 0.0
        self._direction: NDArray[np.float64] | None = None
        self.fit_bands = fit_bands
        self.perimeter = perimeter
        self._sides: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None
        self._smoother: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None = None
        self._face_area: NDArray[np.float64] | None = None
        self._fitted: tuple[float, SurfaceLines] | None = None
        self._pitch: tuple[float, tuple[NDArray[np.float64], NDArray[np.float64]]] | None = None
        # fitted contours leave holes here (band_fit_covers): eq. 9 lines fill them
        self.fill_holes = False
        # stripes only where the component is wider than 2 x this, its narrow walls get
        # their centre line (``narrow_walls``); 0: stripes everywhere
        self.wall_half_width = 0.0
        self._reach: tuple[float, NDArray[np.float64]] | None = None

    def sides(self) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
        """(n,) distances from the longest boundary loop and from all the others; None for
        a component with a single loop (disc-like: eq. 9 is right there)."""
        if self._sides is None:
            from slicer.toolpath.geodesic import distance_from
            from slicer.toolpath.surface import boundary_loops

            loops = boundary_loops(self.faces)
            if len(loops) < 2:
                return None
            length = [float(np.linalg.norm(self.vertices[lp] - self.vertices[np.roll(lp, 1)],
                                           axis=1).sum()) for lp in loops]
            outer = int(np.argmax(length))
            inner = np.concatenate([lp for i, lp in enumerate(loops) if i != outer])
            self._sides = (distance_from(self.vertices, self.faces, loops[outer],
                                         backend=self.backend),
                           distance_from(self.vertices, self.faces, inner, backend=self.backend))
        return self._sides

    def mostly_narrow(self, half_width: float, share: float) -> bool:
        """Whether the band is narrower than 2 x half_width on at least ``share`` of the
        area (``narrow_share``)."""
        return self.narrow_share(half_width, share) >= share

    def narrow_share(self, half_width: float, at_least: float = 0.0) -> float:
        """Share of the area where the band is narrower than 2 x half_width: farther than
        half_width from every point at least half_width from the boundary. Where less than
        ``at_least`` of the area lies within half_width of the boundary, that share (an
        upper bound) without measuring further."""
        if len(self.faces) == 0:
            return 0.0
        total = max(float(self.face_area.sum()), tol.zero)
        near = self.distance[self.faces].mean(axis=1) < half_width
        near_share = float(self.face_area[near].sum()) / total
        if near_share < at_least:
            return near_share  # narrow areas lie within half_width of the boundary: too few
        narrow = self.reach(half_width)[self.faces].mean(axis=1) > half_width
        return float(self.face_area[narrow].sum()) / total

    def reach(self, half_width: float) -> NDArray[np.float64]:
        """(n,) float64, distance (surface units) from the points at least half_width from
        the boundary (inf without any): beyond half_width the band is narrower than
        2 x half_width."""
        if self._reach is None or self._reach[0] != half_width:
            wide = np.flatnonzero(self.distance >= half_width)
            if len(wide) == 0:
                reach = np.full(len(self.vertices), np.inf)
            else:
                from slicer.toolpath.geodesic import distance_from

                reach = distance_from(self.vertices, self.faces, wide, backend=self.backend)
            self._reach = (half_width, reach)
        return self._reach[1]

    def fitted_contours(self, spacing: float) -> SurfaceLines:
        """Contours fitted to the band (``contours.two_sided_contour_lines``) at ``spacing``;
        the last ones are kept, since the coverage check and the volume match's first trial
        ask for the same spacing."""
        if self._fitted is not None and self._fitted[0] == spacing:
            return self._fitted[1]
        from slicer.toolpath.contours import two_sided_contour_lines

        sides = self.sides()
        if sides is None:
            raise ValueError("fitted contours need a band (two or more boundary loops)")
        lines = two_sided_contour_lines(self.vertices, self.faces, *sides, spacing,
                                        pitch_fit=self.band_pitch(spacing))
        self._fitted = (spacing, lines)
        return lines

    def band_pitch(self, spacing: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``contours.band_pitch`` of this band at ``spacing``, blended over PITCH_SMOOTHING
        spacings (the last one kept: the lines and their widths both need it)."""
        if self._pitch is not None and self._pitch[0] == spacing:
            return self._pitch[1]
        from slicer.toolpath.contours import band_pitch

        sides = self.sides()
        if sides is None:
            raise ValueError("a band pitch needs a band (two or more boundary loops)")
        smooth = self.smoother(PITCH_SMOOTHING * spacing) if PITCH_SMOOTHING > 0 else None
        pitch_fit = band_pitch(*sides, spacing, smooth)
        self._pitch = (spacing, pitch_fit)
        return pitch_fit

    def width_scale(self, pattern: int, spacing: float) -> NDArray[np.float64] | None:
        """(n,) float64, the band's local pitch over ``spacing`` (within
        CENTRE_WIDTH_SCALE) for contours fitted to a band, None for any other lines.

        A band of 4.6 spacings holds 5 lines at 0.92 spacings (``fitted_contours``): the
        lines printed at W x this ratio (the nozzle speed sets it, W = C / (H v)) abut
        instead of overlapping by 8 %, and the band gets the ink its area needs. Not where
        eq. 9's iso-lines fill holes in the fitting (no band there, no pitch), and not on
        stripes: their local spacing 2 pi / |grad psi| is off next to the ends
        trim_converging cuts back (tried: the membrane's and the aorta's prints kept more
        gel; README, session 11)."""
        if pattern == Pattern.STRIPE and self.wall_half_width > 0.0:
            # the walls' centre lines as wide as the wall, the stripes at W
            centre = self.centre_scale(spacing)
            if centre is None:
                return None
            wall = self.reach(self.wall_half_width) > self.wall_half_width
            return np.where(wall, centre, 1.0)
        sides = self.sides() if self.fit_bands and pattern == Pattern.CONTOUR else None
        if sides is None or self.fill_holes:
            return None
        pitch, _ = self.band_pitch(spacing)
        return np.asarray(np.clip(pitch / spacing, *CENTRE_WIDTH_SCALE), dtype=np.float64)

    def centre_scale(self, spacing: float) -> NDArray[np.float64] | None:
        """(n,) float64, the local band width d_outer + d_inner over ``spacing`` (within
        CENTRE_WIDTH_SCALE): the one line along a thin band's middle (``centre_lines``)
        printed as wide as the band where it runs, rather than one width for the whole
        band (a band widening from 1 to 1.4 W along a tube's junction); None without a band.
        """
        sides = self.sides()
        if sides is None:
            return None
        return np.asarray(np.clip((sides[0] + sides[1]) / spacing, *CENTRE_WIDTH_SCALE),
                          dtype=np.float64)

    def line_gap(self, lines: SurfaceLines) -> NDArray[np.float64]:
        """(m,) float64, distance (surface units) from each face centre to the nearest
        line segment (inf without lines)."""
        from slicer.toolpath.eikonal import points_to_segments

        p = lines.points
        seg = np.flatnonzero(lines.line[1:] == lines.line[:-1])
        if len(seg) == 0:
            return np.full(len(self.faces), np.inf)
        return points_to_segments(self.vertices[self.faces].mean(axis=1), p[seg], p[seg + 1])

    def band_fit_covers(self, spacing: float) -> bool:
        """Whether contours fitted to the band at ``spacing`` leave no hole: at most
        UNCOVERED_SHARE of the area farther than UNCOVERED x spacing from every line.

        The band model (a whole number of lines between the outer loop and the others)
        holds on a wall; where the component is no band (a junction: a solid spot between
        two holes, the aorta's plaque between its lumens) the lines of the two families
        and the medial line can miss whole areas. True without band fitting."""
        sides = self.sides() if self.fit_bands else None
        if sides is None:
            return True
        hole = self.line_gap(self.fitted_contours(spacing)) > UNCOVERED * spacing
        return float(self.face_area[hole].sum()) <= UNCOVERED_SHARE * self.face_area.sum()

    def fill_band_fit_holes(self, spacing: float) -> bool:
        """Contours of a component that is no band (``band_fit_covers`` fails at
        ``spacing``) get eq. 9's iso-lines where the fitted ones leave holes; whether so."""
        if not self.band_fit_covers(spacing):
            self.fill_holes = True
        return self.fill_holes

    @property
    def face_area(self) -> NDArray[np.float64]:
        """(m,) float64, face areas (surface units^2)."""
        if self._face_area is None:
            from slicer.toolpath.surface import face_normals

            self._face_area = face_normals(self.vertices, self.faces)[1]
        return self._face_area

    def contour_level(self) -> NDArray[np.float64]:
        """(n,) mm, the value contours are printed in increasing order of: the distance
        from the outer loop on a band fitted between two boundaries (outer wall, inwards
        across the band, inner wall last: consecutive lines are neighbours, so they join),
        else the distance from the boundary (outside-in)."""
        sides = self.sides() if self.fit_bands else None
        return self.distance if sides is None else sides[0]

    def smoother(self, length: float) -> Callable[[NDArray[np.float64]], NDArray[np.float64]]:
        """u -> (M + t L)^-1 M u, t = length^2: a heat flow over about ``length`` mm
        (factored once per surface, on the first call)."""
        if self._smoother is None:
            import scipy.sparse as sp

            from slicer.toolpath.surface import cotan_laplacian, lumped_mass, spd_solver

            mass = lumped_mass(self.vertices, self.faces)
            lap = cotan_laplacian(self.vertices, self.faces, robust=True)
            solve = spd_solver((sp.diags(mass) + length * length * lap).tocsc())
            self._smoother = lambda u: np.asarray(solve(mass * u))
        return self._smoother

    @property
    def direction(self) -> NDArray[np.float64]:
        """(m, 3) per-face stripe direction (computed on first use)."""
        if self._direction is None:
            from slicer.toolpath.surface import stripe_direction

            self._direction = stripe_direction(self.vertices, self.faces, self.distance)
        return self._direction

    def centre_lines(self) -> SurfaceLines:
        """One line along the middle of a band with holes, where the distances from the
        longest boundary loop and from the others are equal (empty with a single loop).

        Why not the 1/2 level of a harmonic function (0 on one side, 1 on the other): on a
        curved band it sits off the middle (an annulus: at the geometric mean radius; a
        tube's 2.5 mm wall: 0.05 mm inwards, one voxel of the virtual print)."""
        from slicer.toolpath.isolines import iso_lines
        from slicer.toolpath.lines import empty_lines

        sides = self.sides()
        if sides is None:
            return empty_lines()
        d_out, d_in = sides
        u = d_out / np.maximum(d_out + d_in, tol.zero)
        return iso_lines(self.vertices, self.faces, u, np.array([0.5]))

    def narrow_walls(self, stripes: SurfaceLines) -> SurfaceLines:
        """``stripes`` kept where the component is at least 2 x wall_half_width wide, and
        the centre line (``centre_lines``) along its narrower walls: across a wall about one
        width wide stripes are stubs joined by U-turn connectors, which then lay half the
        ink, and the volume match spreads the stripes of the wide part apart to make up
        for it (the aorta's plaque junction: two tube walls and the bridge between them)."""
        from slicer.toolpath.lines import merge_lines
        from slicer.toolpath.perimeter import clip_lines

        hw = self.wall_half_width
        reach = self.reach(hw)
        wide = clip_lines(stripes, self.vertices, self.faces, -reach, -hw)
        walls = clip_lines(self.centre_lines(), self.vertices, self.faces, reach, hw)
        ident = np.arange(len(self.faces))
        return merge_lines([walls, wide], [ident, ident])

    def lines(self, pattern: int, spacing: float, poisson: bool = False) -> SurfaceLines:
        """Contours or stripes at ``spacing`` on this surface (its units).

        Contours start half a spacing inside the boundary, or half the largest boundary
        distance where the component is narrower than one spacing (a thin band then still
        gets a loop along its middle).
        """
        if pattern == Pattern.CONTOUR:
            from slicer.toolpath.contours import contour_lines

            sides = self.sides() if self.fit_bands else None
            if sides is not None:
                fitted = self.fitted_contours(spacing)
                if not self.fill_holes:
                    return fitted
                # where the component is no band, eq. 9's iso-lines of the boundary
                # distance fill the holes the fitted lines leave
                hole = np.flatnonzero(self.line_gap(fitted) > UNCOVERED * spacing)
                if hole.size == 0:
                    return fitted
                from slicer.toolpath.lines import merge_lines

                extra = contour_lines(self.vertices, self.faces[hole], self.distance, spacing,
                                      0.5 * spacing)
                return merge_lines([fitted, extra], [np.arange(len(self.faces)), hole])
            offset = min(0.5 * spacing, 0.5 * self.max_distance)
            return contour_lines(self.vertices, self.faces, self.distance, spacing, offset)
        from slicer.toolpath.stripes import poisson_stripe_lines, stripe_lines

        fn = poisson_stripe_lines if poisson else stripe_lines
        stripes = fn(self.vertices, self.faces, self.direction, spacing)
        if self.wall_half_width > 0.0:
            return self.narrow_walls(stripes)
        from slicer.toolpath.perimeter import PERIMETER_MIN_DISTANCE

        if not self.perimeter or self.max_distance < PERIMETER_MIN_DISTANCE * spacing:
            return stripes
        from slicer.toolpath.lines import merge_lines
        from slicer.toolpath.perimeter import PERIMETER_CLIP, clip_lines, perimeter_loop

        loop = perimeter_loop(self.vertices, self.faces, self.distance, spacing)
        inner = clip_lines(stripes, self.vertices, self.faces, self.distance,
                           PERIMETER_CLIP * spacing)
        ident = np.arange(len(self.faces))
        return merge_lines([loop, inner], [ident, ident])


class _Measured(NamedTuple):
    """Width error at the line points with a measured spacing (dimensionless)."""

    error: NDArray[np.float64]  # (k,) |spacing - target| / target, target the pair's mean W
    pointwise: NDArray[np.float64]  # (k,) |spacing - W| / W, W at the point alone
    lone: int  # how many of the k points are on lone lines, measured by their band


def _measure(lines: SurfaceLines, width_pt: NDArray[np.float64],
             normals_pt: NDArray[np.float64],
             boundary: Callable[[], tuple[NDArray[np.float64], NDArray[np.float64]]]
             ) -> _Measured:
    """The width error of ``lines`` printed at ``width_pt`` ((P,) float64 mm).

    Two neighbouring lines tile the layer when they lie (W_a + W_b) / 2 apart, each covering
    half its own width on either side; that mean, of the width at the point and at its foot
    on the neighbouring line, is the target of the spacing. Measured against the point's W
    alone (``pointwise``, the measure before session 13), a layer whose W changes across
    one spacing is always off: its nearest neighbour lies on the narrower side, half the
    change away from W (the membrane's dome layers, W 2.5-7 mm: -10 % on every interior
    ring, however well the lines follow eq. 14).

    A lone line fills a band about one width wide by itself (a thin wall, a tube's shell):
    its nearest other line lies across the part, not beside it, so its spacing is the
    band's width there: the distances to the boundary on its two sides (Euclidean: exact
    on flat layers, and a band that thin is nearly flat across), against its own W.
    ``boundary`` gives the (B, 3) mm ends a, b of the original layer's boundary segments
    (called when needed).
    """
    from slicer.toolpath.width_error import band_width, line_neighbours

    if len(lines.points) < 2:
        return _Measured(np.zeros(0), np.zeros(0), 0)
    near = line_neighbours(lines.points, lines.line, normals_pt, closed=lines.closed)
    spacing = near.spacing.copy()
    target = 0.5 * (width_pt + near.at_foot(width_pt))
    lone = ~np.isfinite(spacing) | (spacing > LONE_LINE * width_pt)
    if lone.any():
        spacing[lone] = band_width(lines.points[lone], *boundary())
        target[lone] = width_pt[lone]
    ok = np.isfinite(spacing) & (width_pt > 0) & (target > 0)
    return _Measured(np.abs(spacing[ok] - target[ok]) / target[ok],
                     np.abs(spacing[ok] - width_pt[ok]) / width_pt[ok],
                     int(np.count_nonzero(lone & ok)))


@dataclass(frozen=True, eq=False)
class _Built:
    lines: SurfaceLines
    linked: LinkedPath
    waypoints: Waypoints
    flow: float = 1.0  # deposited volume per length over the profile's (fit_flow)
    # (n,) per-vertex width / W(H) the lines print at (pitch-following contours), or None
    scale: NDArray[np.float64] | None = None


class _Component:
    """One layer component on its own vertex numbering, with its process fields."""

    def __init__(self, layer: LayerMesh, face_ids: NDArray[np.int64], pattern: int,
                 cfg: ToolpathConfig, profile: ExtrusionProfile) -> None:
        used, faces = _compact(layer.vertices, layer.faces[face_ids])
        vertices = layer.vertices[used]
        height = np.maximum(layer.height[used], 0.0)
        direction = layer.direction[used]
        # a vertex where the boundary distance peaks inside a triangle (a disc's centre):
        # else the innermost lines stop short of it and leave a pocket of gel (peaks.py)
        vertices, split, parent, bary = add_distance_peaks(
            vertices, faces, profile.width(np.maximum(height, profile.layer_height_range[0])))
        if len(parent):
            height = np.concatenate([height, interpolate(height, faces, parent, bary)])
            between = interpolate(direction, faces, parent, bary)
            direction = np.concatenate([direction, between / np.maximum(
                np.linalg.norm(between, axis=1, keepdims=True), tol.zero)])
            faces = split
        self.vertices = vertices
        self.faces = faces
        # H as sliced (for the required volume) and H as printed: raised to the profile's
        # smallest, because W = C / (H v) diverges as H -> 0 where the speed saturates.
        # Above the table H stays: the speed saturates at the slowest, and W = C / (H v)
        # is the pitch that slab needs from that filament (clamping H there too overstated
        # W, up to 8 mm where a 3 mm slab needs lines 4.4 mm apart)
        self.height_sliced = height
        self.height = np.maximum(self.height_sliced, profile.layer_height_range[0])
        self.direction = direction
        self.pattern = pattern
        self.cfg = cfg
        self.profile = profile
        self.width = profile.width(self.height)
        # the profile table's speeds: a width scaled by the speed stays within them
        self.v_lo, self.v_hi = (float(x) for x in profile.speed_for_height(
            np.array(profile.height_range[::-1])))
        self.w_mean = _mean_width(self.vertices, faces, self.width)
        self.normals = face_normals(self.vertices, faces, self.direction)
        self.vertex_normals = vertex_normals(self.vertices, faces, self.direction)
        self.graph = mesh_graph(self.vertices, faces)
        self.neighbours = face_neighbours(faces)

    def values_at(self, face: NDArray[np.int32], bary: NDArray[np.float64],
                  scale: NDArray[np.float64] | None = None) -> tuple[
        NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]
    ]:
        """(H, v, W) at surface points: H interpolated, v = f(H / beta), W = C / (H v);
        with ``scale`` ((n,) per vertex) the speed is divided by it, so W is multiplied by
        it (``flowed_speed``)."""
        h = np.maximum(interpolate(self.height, self.faces, face, bary),
                       self.profile.layer_height_range[0])
        v = self.profile.speed_at(h)
        if scale is not None:
            v = self.flowed_speed(v, interpolate(scale, self.faces, face, bary))
        return h, v, self.profile.rate_mm3_s / (h * v)

    def flowed_speed(self, speed: NDArray[np.float64], flow: NDArray[np.float64] | float,
                     nominal: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """Speed of lines printed at ``flow`` x the volume per length of ``speed``: divided
        by ``flow``, never beyond the table's speeds unless it already was; with
        ``nominal`` (the profile's speed at H) the width stays within CENTRE_WIDTH_SCALE of
        W(H) however many scalings compound (a centre line's band width, then the flow fit)."""
        v = speed / flow
        if nominal is not None:
            v = np.clip(v, nominal / CENTRE_WIDTH_SCALE[1], nominal / CENTRE_WIDTH_SCALE[0])
        return np.clip(v, np.minimum(self.v_lo, speed), np.maximum(self.v_hi, speed))

    def build(self, lines_found: SurfaceLines, level_of: NDArray[np.float64] | None,
              spacing: float, start: NDArray[np.float64], lifter: Lifter, lift: float,
              trim_distance: NDArray[np.float64] | None = None, link: bool = True,
              join: float | None = None, scale: NDArray[np.float64] | None = None
              ) -> _Built:
        """Map back, drop short fragments, resample, order, link; values per waypoint.

        Args:
            lines_found: lines on the (deformed) surface.
            level_of: (n,) per-vertex boundary distance ordering contours, None for stripes.
            spacing: line spacing on the surface the lines were found on (its units).
            start: (3,) nozzle position before the component.
            lifter, lift: travel clearance.
            trim_distance: (n,) boundary distance on the lines' surface: open line ends
                closer than spacing / 4 to the boundary are cut back by W / 2.
            link: False stops after resampling (lines only: for width measurements).
            join: connectors up to this x W extrude (default: the config's join_factor).
            scale: (n,) per-vertex factor on W the lines print at (``values_at``), or None.
        """
        lines = map_back(lines_found, self.vertices, self.faces)
        lines = drop_short_lines(lines, self.cfg.min_path_length_mm)
        _, _, w_pt = self.values_at(lines.face, lines.bary, scale)
        kept = drop_tiny_loops(lines, w_pt, TINY_LOOP)
        if kept is not lines:
            lines = kept
            _, _, w_pt = self.values_at(lines.face, lines.bary, scale)
        trim = None
        if trim_distance is not None and lines.n_lines:
            # An open line ending on the boundary stops half a width inside it: its band of
            # material then ends at the boundary, and the U-turn connector to the next line
            # runs along the boundary inside the layer (not half outside it).
            idx = line_index(lines)
            ends = np.stack([idx.start, np.maximum(idx.stop - 1, idx.start)], axis=1)
            d_end = interpolate(trim_distance, self.faces, lines.face[ends.ravel()],
                                lines.bary[ends.ravel()]).reshape(-1, 2)
            # (at most a quarter of the line per end: a short stripe across a narrow band
            # keeps half its length rather than vanishing)
            cap = 0.25 * line_lengths(lines)[:, None]
            trim = np.where(d_end < 0.25 * spacing, np.minimum(0.5 * w_pt[ends], cap), 0.0)
        lines = resample_lines(lines, self.vertices, self.faces, self.cfg.waypoint_spacing * w_pt,
                               neighbours=self.neighbours, trim=trim)
        lines = drop_short_lines(lines, self.cfg.min_path_length_mm)
        if not link:
            empty = link_pieces(lines, [], self.vertices, self.faces, self.graph,
                                np.zeros(0), lifter, lift)
            return _Built(lines, empty, self._waypoints(empty, scale), scale=scale)
        _, _, w_rs = self.values_at(lines.face, lines.bary, scale)
        level = None
        if level_of is not None:
            level = line_levels(lines, interpolate(level_of, self.faces, lines.face, lines.bary))
        factor = self.cfg.join_factor if join is None else join
        joiner = Joiner(lines, self.vertices, self.faces, self.graph, w_rs, lifter, factor)
        if level is None and lines.n_lines:
            ids = line_index(lines)
            joiner.prefetch(np.concatenate([ids.start, np.maximum(ids.stop - 1, ids.start)]))
        pieces = order_lines(lines, start, level, spacing, factor * w_rs, joiner.can_join,
                             closed_first=self.cfg.stripe_perimeter
                             and self.pattern == Pattern.STRIPE)
        linked = link_pieces(lines, pieces, self.vertices, self.faces, self.graph, w_rs,
                             lifter, lift, factor, joiner)
        return _Built(lines, linked, self._waypoints(linked, scale), scale=scale)

    def _waypoints(self, linked: LinkedPath, scale: NDArray[np.float64] | None = None
                   ) -> Waypoints:
        n = len(linked.points)
        h, v, w = np.zeros(n), np.zeros(n), np.zeros(n)
        normal = linked.normal.copy()
        on = linked.face >= 0
        h[on], v[on], w[on] = self.values_at(linked.face[on], linked.bary[on], scale)
        normal[on] = point_normals(self.vertex_normals, self.faces, self.normals,
                                   linked.face[on], linked.bary[on])
        if np.any(~on) and np.any(on):
            # travel points copy the process values of the previous surface point
            src = np.maximum.accumulate(np.where(on, np.arange(n), -1))
            first_on = int(np.argmax(on))
            src = np.where(src < 0, first_on, src)
            h, v, w = h[src], v[src], w[src]
        return Waypoints(linked.points, normal, h, w, v, linked.extrude, linked.path,
                         np.full(n, self.pattern, np.int8))


def _component_toolpath(
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
            volume_status="failed", volume_trace=(), deform_status="failed",
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
    from slicer.toolpath.deform import deform_to_constant_width

    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    comp = _Component(layer, face_ids, pattern, cfg, profile)
    spread = float((comp.width.max() - comp.width.min()) / max(comp.w_mean, tol.zero))
    deform_status = "skipped"
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
    surf = _Surface(deformed, comp.faces, cfg.fit_bands, perimeter, cfg.boundary_distance)
    timings["distance"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    required = required_volume(comp.vertices, comp.faces, comp.height_sliced)

    def run(surface: _Surface, used: int, tau: float | None = None, poisson: bool = False,
            join: float | None = None) -> VolumeMatch[_Built]:
        """Lines of pattern ``used`` on ``surface``, volume-matched; with a fixed ``tau``
        only the lines (no linking: for the baseline width measurements)."""
        level_of = surface.contour_level() if used == Pattern.CONTOUR else None
        trim_of = surface.distance if used == Pattern.STRIPE else None

        def evaluate(t: float) -> tuple[float, _Built]:
            spacing = t * comp.w_mean
            lines = surface.lines(used, spacing, poisson)
            scale = surface.width_scale(used, spacing) if cfg.pitch_width else None
            built = comp.build(lines, level_of, spacing, start, lifter, lift, trim_of,
                               link=tau is None, join=join, scale=scale)
            return float(built.waypoints.deposited().sum()), built

        if tau is not None:
            return match_volume(evaluate, required, cfg.volume_tolerance, tau, 1)
        return match_volume(evaluate, required, cfg.volume_tolerance)

    def flowed_width(width: NDArray[np.float64], speed: NDArray[np.float64], flow: float,
                     nominal: NDArray[np.float64]) -> NDArray[np.float64]:
        """W of those lines (W = C / (H v): W x v stays)."""
        return (width if flow == 1.0
                else width * speed / comp.flowed_speed(speed, flow, nominal))

    def fit_flow(built: _Built) -> _Built:
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

    def centre_match(lines: SurfaceLines) -> VolumeMatch[_Built]:
        """One line along a band too narrow (or too wide) for W: its width is scaled to the
        band by the nozzle speed, point by point with ``pitch_width`` (``centre_scale``),
        then as a whole to the volume (``fit_flow``)."""
        scale = surf.centre_scale(comp.w_mean) if cfg.pitch_width else None

        def fixed_lines(t: float) -> tuple[float, _Built]:
            built = fit_flow(comp.build(lines, None, comp.w_mean, start, lifter, lift,
                                        scale=scale))
            return float(built.waypoints.deposited().sum()), built

        return match_volume(fixed_lines, required, cfg.volume_tolerance, 1.0, 1)

    def boundary() -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        from slicer.toolpath.surface import boundary_edges

        edges = boundary_edges(comp.faces)
        return comp.vertices[edges[:, 0]], comp.vertices[edges[:, 1]]

    def measure(lines: SurfaceLines, flow: float = 1.0,
                scale: NDArray[np.float64] | None = None) -> _Measured:
        """Width error of ``lines`` against the width they print at ``flow`` (and the
        per-vertex width ``scale``)."""
        h_pt, v_pt, w_pt = comp.values_at(lines.face, lines.bary, scale)
        return _measure(lines, flowed_width(w_pt, v_pt, flow, comp.profile.speed_at(h_pt)),
                        comp.normals[lines.face], boundary)

    def p90(m: VolumeMatch[_Built]) -> float:
        """p90 of the measured width error of a candidate (inf where nothing could be
        measured: such a candidate never wins a comparison)."""
        err = measure(m.result.lines, m.result.flow, m.result.scale).error
        return float(np.percentile(err, 90)) if len(err) else float("inf")

    def run_joined(surface: _Surface, used: int) -> VolumeMatch[_Built]:
        """``run``; where the match fails with the configured joins, also with short ones,
        keeping the better match."""
        match = run(surface, used)
        if abs(match.rel_error) > SHORT_JOIN_ABOVE and cfg.join_factor > SHORT_JOIN:
            # Longer extruding joins make V(tau) jumpy (a join that flips adds or removes
            # a whole connector); where the match fails with them, e.g. on narrow bands
            # whose short lines make connectors a large share of the volume, link with
            # short joins only and keep whichever matches the volume better.
            short = run(surface, used, join=SHORT_JOIN)
            if abs(short.rel_error) < abs(match.rel_error):
                match = short
        return match

    used = pattern
    fallback = ""
    if (pattern == Pattern.STRIPE
            and surf.mostly_narrow(0.5 * NARROW_STRIPES * comp.w_mean, NARROW_SHARE)):
        # stripes across a band this narrow are shorter than W once their ends are cut back
        # by W / 2: a zig-zag of stubs and connectors. A component that is mostly such a
        # band (a thin wall, a tube's shell, with or without a wider spot) is printed as on
        # a contour layer; there is no across-the-band direction to stagger anyway.
        used, fallback = Pattern.CONTOUR, "contour"
    # partly such walls (a junction between two tubes): also tried with stripes on the wide
    # part only and the walls' centre lines (``_Surface.narrow_walls``)
    walls = (used == Pattern.STRIPE and cfg.fit_bands
             and surf.narrow_share(0.5 * NARROW_STRIPES * comp.w_mean, WALL_SHARE) >= WALL_SHARE
             and surf.sides() is not None)
    # contours with fit_bands: a band narrower than 1.5 W everywhere holds round(b / W) = 1
    # line, the centre line, whose width is then fitted to the band (centre_match)
    thin = 0.5 * THIN_BAND_FIT if cfg.fit_bands and used == Pattern.CONTOUR else THIN_BAND
    centre = surf.centre_lines() if surf.max_distance < thin * comp.w_mean else None
    if centre is not None and centre.n_lines:
        # A band with holes at most about one width wide holds one line: along its middle.
        match, used, fallback = centre_match(centre), Pattern.CONTOUR, "centre-line"
    else:
        no_band = used == Pattern.CONTOUR and surf.fill_band_fit_holes(comp.w_mean)
        if no_band:
            fallback = fallback or "holes-filled"
        match = run_joined(surf, used)
        if no_band and abs(match.rel_error) <= FLOW_FIT_ABOVE:
            # No band: the fitted lines with eq. 9's in their holes, or eq. 9 alone (a
            # disc with slits at its rim, the membrane's dome top: p90 13 -> 12 %, p95
            # 44 -> 15 %; the aorta's plaque junctions keep the fitted lines, whose tail is
            # shorter there): the lines that keep their spacing better, p90 of the error
            plain = _Surface(deformed, comp.faces, False, perimeter, cfg.boundary_distance)
            alt = run_joined(plain, used)
            if abs(alt.rel_error) <= FLOW_FIT_ABOVE and p90(alt) < p90(match):
                surf, match, fallback = plain, alt, "no-band"
        if walls:
            # kept where the lines keep their spacing better (the aorta's plaque junction:
            # stripe p90 34 -> 21 %; a plate with two holes, whose junction is short stubs
            # either way, keeps the stripes everywhere)
            surf.wall_half_width = 0.5 * NARROW_STRIPES * comp.w_mean
            alt = run_joined(surf, used)
            if (abs(alt.rel_error) <= max(FLOW_FIT_ABOVE, abs(match.rel_error))
                    and p90(alt) < p90(match)):
                match, fallback = alt, "walls"
            else:
                surf.wall_half_width = 0.0
    if abs(match.rel_error) > THIN_SHORTFALL and fallback != "centre-line":
        # A band about one width wide: stripes across it vanish once their ends are cut
        # back by W / 2, contours come out as a doubled loop. Try the other pattern and a
        # single line along the middle (bands with holes); keep the closest volume.
        options = [(match, used, fallback)]
        if used == Pattern.STRIPE:
            options.append((run(surf, Pattern.CONTOUR), Pattern.CONTOUR, "contour"))
        centre = surf.centre_lines() if centre is None else centre
        if centre.n_lines:
            options.append((centre_match(centre), Pattern.CONTOUR, "centre-line"))
        match, used, fallback = min(options, key=lambda o: abs(o[0].rel_error))
    if abs(match.rel_error) > FLOW_FIT_ABOVE and fallback != "centre-line":
        # The line count is discrete (a band of 1.7 W holds 2 lines, not 1.7): where no
        # spacing matches the volume, the flow per length does.
        fitted = fit_flow(match.result)
        volume = float(fitted.waypoints.deposited().sum())
        match = replace(match, volume=volume, rel_error=volume / required - 1.0,
                        status=f"{match.status}+flow", result=fitted)
    timings["lines"] = time.perf_counter() - t0
    built = match.result

    t0 = time.perf_counter()
    # against the width the waypoints carry (flow-fitted components print wider or
    # narrower lines on purpose), and against the profile's W(H) for comparison
    measured = measure(built.lines, built.flow, built.scale)
    err_nominal = (measured.error if built.flow == 1.0 and built.scale is None
                   else measure(built.lines).error)
    err_undeformed = np.zeros(0)
    err_poisson = np.zeros(0)
    if measure_baselines:
        if deformed is comp.vertices or fallback == "centre-line":
            b = built  # no deformation (or one line): the direct lines are the lines
        else:
            direct = _Surface(comp.vertices, comp.faces,
                              cfg.fit_bands and fallback != "no-band", perimeter,
                              cfg.boundary_distance)
            if used == Pattern.CONTOUR:
                direct.fill_band_fit_holes(comp.w_mean)
            direct.wall_half_width = surf.wall_half_width
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


def layer_toolpath(layer: LayerMesh, pattern: int, cfg: ToolpathConfig,
                   profile: ExtrusionProfile, measure_baselines: bool = True) -> LayerResult:
    """All components of one layer in nearest-neighbour order, joined by travel moves.
    Layer 0 uses ``cfg.first_layer_beta`` instead of the profile's beta when it is set."""
    from slicer.toolpath.surface import components

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
        res = _component_toolpath(layer, comps[ci], pattern, cfg, profile, pos, lifter, lift,
                                  measure_baselines)
        wp = res.waypoints
        if len(wp.position) == 0:
            results.append(res)
            continue
        if parts:
            prev = parts[-1]
            tp, tn = lifter.travel(prev.position[-1], wp.position[0], lift,
                                   2.0 * float(prev.width[-1]))
            parts.append(_travel(tp, tn, prev, -1))
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


def _travel(points: NDArray[np.float64], normals: NDArray[np.float64], like: Waypoints,
            at: int) -> Waypoints:
    """Travel waypoints (extrude=False, one path) with the process values of ``like[at]``."""
    k = len(points)
    return Waypoints(
        position=points,
        normal=normals,
        height=np.full(k, like.height[at]),
        width=np.full(k, like.width[at]),
        speed=np.full(k, like.speed[at]),
        extrude=np.zeros(k, dtype=bool),
        path=np.zeros(k, dtype=np.int32),
        pattern=np.full(k, like.pattern[at], np.int8),
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


def _run_chunk(args: tuple[list[LayerMesh], str, ToolpathConfig, ExtrusionProfile, bool]
               ) -> list[LayerResult]:
    meshes, first, cfg, profile, baselines = args
    return [layer_toolpath(m, layer_pattern(m.index, first), cfg, profile, baselines)
            for m in meshes if len(m.faces)]


def compute_toolpath(
    layers: Layers,
    config: JobConfig,
    profile: ExtrusionProfile,
    progress: Progress | None = None,
    measure_baselines: bool = True,
    workers: int = 2,
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
            results.extend(_run_chunk(([m], cfg.first_pattern, cfg, profile, measure_baselines)))
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
                                                measure_baselines)) for c in chunks]
            for fut in as_completed(futures):
                part = fut.result()
                results.extend(part)
                done += len(part)
                report_progress(done / len(meshes), f"{done}/{len(meshes)} layers")
    results.sort(key=lambda r: r.index)
    toolpath, stats = assemble(results)
    report, errors, status, timings = _report(results, toolpath, profile)
    # without them width_error_undeformed and width_error_poisson_stripe have n = 0
    report["baselines_measured"] = measure_baselines
    timings["total"] = time.perf_counter() - t_start
    report["timing_s"] = {k: round(v, 3) for k, v in timings.items()}
    report["per_layer"] = stats
    return ToolpathResult(toolpath, report, stats, errors, status, timings)


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
            trav = _travel(tp, tn, last, -1)
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


def _pct(values: NDArray[np.float64]) -> dict[str, float | int]:
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


def _report(results: list[LayerResult], tp: Toolpath, profile: ExtrusionProfile) -> tuple[
    dict[str, Any], dict[str, dict[str, NDArray[np.float64]]], str, dict[str, float]
]:
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
                          for kind in ("contour", "centre-line")},
        # contour components that are no band (fitted lines left holes, eq. 9 lines fill them)
        "band_fit_holes_filled": sum(c.fallback == "holes-filled" for c in comps),
        # no band, and eq. 9's contours alone kept their spacing better than the fitted ones
        "band_fit_dropped": sum(c.fallback == "no-band" for c in comps),
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
    status = "ok" if set(statuses) <= {"converged", "converged-scan"} else "volume"
    if failed:
        status = "failed-components"
    return report, errors, status, timings
