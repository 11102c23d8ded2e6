"""The line source: contours or stripes of one (possibly deformed) component surface.

``SurfaceGeometry`` holds what the line generators derive from the surface alone (boundary
distance, the distances from the outer loop and from the others, the stripe direction, the
band's pitch), each computed on first use and then kept. ``LineSource`` is that geometry
with the options a component is tried with (band fitting, a stripe perimeter, eq. 9's lines
in the band fit's holes, centre lines along narrow walls): an immutable value, so trying an
option is ``dataclasses.replace(source, option=...)``, which shares the geometry's caches.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import Literal

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from slicer.stages import PATTERN_CONTOUR, PATTERN_STRIPE
from slicer.tolerance import tol
from slicer.toolpath.contours import band_pitch, contour_lines, two_sided_contour_lines
from slicer.toolpath.eikonal import points_to_segments
from slicer.toolpath.geodesic import boundary_distance, distance_from
from slicer.toolpath.isolines import iso_lines
from slicer.toolpath.lines import SurfaceLines, empty_lines, merge_lines
from slicer.toolpath.perimeter import (
    PERIMETER_CLIP,
    PERIMETER_MIN_DISTANCE,
    clip_lines,
    perimeter_loop,
)
from slicer.toolpath.stripes import poisson_stripe_lines, stripe_lines
from slicer.toolpath.surface import (
    boundary_loops,
    cotan_laplacian,
    face_normals,
    lumped_mass,
    spd_solver,
    stripe_direction,
)

PITCH_SMOOTHING = 2.0  # contour pitch blended over this x W where the line count changes
CENTRE_WIDTH_SCALE = (0.5, 1.5)  # a line's width may be scaled by the nozzle speed this far
UNCOVERED = 0.8  # band fitting fails where an area is farther than this x spacing from lines
UNCOVERED_SHARE = 0.02  # ... more than this share of the component (eq. 9 lines fill them)

Backend = Literal["eikonal", "heat"]
Sides = tuple[NDArray[np.float64], NDArray[np.float64]]
PitchFit = tuple[NDArray[np.float64], NDArray[np.float64]]


@dataclass(frozen=True, eq=False)
class SurfaceGeometry:
    """One component surface and what is derived from it alone (cached on first use).

    Attributes:
        vertices: (n, 3) float64, surface units (mm, or deformed mm).
        faces: (m, 3) int32.
        backend: boundary distance solver (``geodesic.boundary_distance``).
    """

    vertices: NDArray[np.float64]
    faces: NDArray[np.int32]
    backend: Backend = "eikonal"
    # the last value asked for per argument (a volume match asks for one spacing twice in a
    # row: the coverage check, then its first trial); the smoother: the first one
    _reach: dict[float, NDArray[np.float64]] = field(default_factory=dict, repr=False)
    _fitted: dict[float, SurfaceLines] = field(default_factory=dict, repr=False)
    _pitch: dict[float, PitchFit] = field(default_factory=dict, repr=False)
    _smoother: list[Callable[[NDArray[np.float64]], NDArray[np.float64]]] = field(
        default_factory=list, repr=False)

    @cached_property
    def distance(self) -> NDArray[np.float64]:
        """(n,) float64, geodesic distance to the boundary (contours, stripe directions,
        trims, perimeters)."""
        return boundary_distance(self.vertices, self.faces, backend=self.backend)

    @cached_property
    def max_distance(self) -> float:
        """Largest boundary distance (0 without vertices)."""
        return float(self.distance.max()) if len(self.distance) else 0.0

    @cached_property
    def sides(self) -> Sides | None:
        """(n,) distances from the longest boundary loop and from all the others; None for
        a component with a single loop (disc-like: eq. 9 is right there)."""
        loops = boundary_loops(self.faces)
        if len(loops) < 2:
            return None
        length = [float(np.linalg.norm(self.vertices[lp] - self.vertices[np.roll(lp, 1)],
                                       axis=1).sum()) for lp in loops]
        outer = int(np.argmax(length))
        inner = np.concatenate([lp for i, lp in enumerate(loops) if i != outer])
        return (distance_from(self.vertices, self.faces, loops[outer], backend=self.backend),
                distance_from(self.vertices, self.faces, inner, backend=self.backend))

    @cached_property
    def face_area(self) -> NDArray[np.float64]:
        """(m,) float64, face areas (surface units^2)."""
        return face_normals(self.vertices, self.faces)[1]

    @cached_property
    def direction(self) -> NDArray[np.float64]:
        """(m, 3) float64, unit per-face stripe direction."""
        return stripe_direction(self.vertices, self.faces, self.distance)

    def reach(self, half_width: float) -> NDArray[np.float64]:
        """(n,) float64, distance (surface units) from the points at least half_width from
        the boundary (inf without any): beyond half_width the band is narrower than
        2 x half_width."""
        if half_width not in self._reach:
            wide = np.flatnonzero(self.distance >= half_width)
            reach = (np.full(len(self.vertices), np.inf) if len(wide) == 0 else
                     distance_from(self.vertices, self.faces, wide, backend=self.backend))
            self._reach.clear()
            self._reach[half_width] = reach
        return self._reach[half_width]

    def smoother(self, length: float) -> Callable[[NDArray[np.float64]], NDArray[np.float64]]:
        """u -> (M + t L)^-1 M u, t = length^2: a heat flow over about ``length`` mm,
        factored once per surface at the first length asked (the spacings one volume match
        tries differ by a few per cent)."""
        if not self._smoother:
            mass = lumped_mass(self.vertices, self.faces)
            lap = cotan_laplacian(self.vertices, self.faces, robust=True)
            solve = spd_solver((sp.diags(mass) + length * length * lap).tocsc())
            self._smoother.append(lambda u: np.asarray(solve(mass * u)))
        return self._smoother[0]

    def band_pitch(self, spacing: float) -> PitchFit:
        """``contours.band_pitch`` of this band at ``spacing``, blended over PITCH_SMOOTHING
        spacings."""
        if spacing not in self._pitch:
            sides = self.sides
            if sides is None:
                raise ValueError("a band pitch needs a band (two or more boundary loops)")
            smooth = self.smoother(PITCH_SMOOTHING * spacing) if PITCH_SMOOTHING > 0 else None
            pitch_fit = band_pitch(*sides, spacing, smooth)
            self._pitch.clear()
            self._pitch[spacing] = pitch_fit
        return self._pitch[spacing]

    def fitted_contours(self, spacing: float) -> SurfaceLines:
        """Contours fitted to the band (``contours.two_sided_contour_lines``) at ``spacing``."""
        if spacing not in self._fitted:
            sides = self.sides
            if sides is None:
                raise ValueError("fitted contours need a band (two or more boundary loops)")
            lines = two_sided_contour_lines(self.vertices, self.faces, *sides, spacing,
                                            pitch_fit=self.band_pitch(spacing))
            self._fitted.clear()
            self._fitted[spacing] = lines
        return self._fitted[spacing]

    def centre_lines(self) -> SurfaceLines:
        """One line along the middle of a band with holes, where the distances from the
        longest boundary loop and from the others are equal (empty with a single loop).

        Why not the 1/2 level of a harmonic function (0 on one side, 1 on the other): on a
        curved band it sits off the middle (an annulus: at the geometric mean radius)."""
        sides = self.sides
        if sides is None:
            return empty_lines()
        d_out, d_in = sides
        u = d_out / np.maximum(d_out + d_in, tol.zero)
        return iso_lines(self.vertices, self.faces, u, np.array([0.5]))

    def centre_scale(self, spacing: float) -> NDArray[np.float64] | None:
        """(n,) float64, the local band width d_outer + d_inner over ``spacing`` (within
        CENTRE_WIDTH_SCALE): the one line along a thin band's middle printed as wide as the
        band where it runs, rather than one width for the whole band; None without a band.
        """
        sides = self.sides
        if sides is None:
            return None
        return np.asarray(np.clip((sides[0] + sides[1]) / spacing, *CENTRE_WIDTH_SCALE),
                          dtype=np.float64)

    def line_gap(self, lines: SurfaceLines) -> NDArray[np.float64]:
        """(m,) float64, distance (surface units) from each face centre to the nearest
        line segment (inf without lines)."""
        p = lines.points
        seg = np.flatnonzero(lines.line[1:] == lines.line[:-1])
        if len(seg) == 0:
            return np.full(len(self.faces), np.inf)
        return points_to_segments(self.vertices[self.faces].mean(axis=1), p[seg], p[seg + 1])

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

    def mostly_narrow(self, half_width: float, share: float) -> bool:
        """Whether the band is narrower than 2 x half_width on at least ``share`` of the
        area (``narrow_share``)."""
        return self.narrow_share(half_width, share) >= share


@dataclass(frozen=True, eq=False)
class LineSource:
    """Contours or stripes of one surface with the options a component is tried with.

    Attributes:
        geometry: the surface and its cached derived fields (shared by ``replace``).
        fit_bands: contours of a band (two or more loops) fitted between its sides.
        perimeter: stripes get one loop inside the boundary (``perimeter.py``).
        fill_holes: the fitted contours leave holes (``band_fit_covers``): eq. 9's lines
            fill them.
        wall_half_width: stripes only where the component is wider than 2 x this, its
            narrow walls get their centre line (``narrow_walls``); 0: stripes everywhere.
    """

    geometry: SurfaceGeometry
    fit_bands: bool = True
    perimeter: bool = False
    fill_holes: bool = False
    wall_half_width: float = 0.0

    @staticmethod
    def of(vertices: NDArray[np.float64], faces: NDArray[np.int32], fit_bands: bool = True,
           perimeter: bool = False, distance: Backend = "eikonal") -> LineSource:
        """The line source of a new surface."""
        return LineSource(SurfaceGeometry(vertices, faces, distance), fit_bands, perimeter)

    @property
    def vertices(self) -> NDArray[np.float64]:
        """(n, 3) float64, surface units."""
        return self.geometry.vertices

    @property
    def faces(self) -> NDArray[np.int32]:
        """(m, 3) int32."""
        return self.geometry.faces

    @property
    def distance(self) -> NDArray[np.float64]:
        """(n,) float64, boundary distance."""
        return self.geometry.distance

    @property
    def face_area(self) -> NDArray[np.float64]:
        """(m,) float64, face areas."""
        return self.geometry.face_area

    def band_sides(self) -> Sides | None:
        """The band's two side distances where contours are fitted to it, else None."""
        return self.geometry.sides if self.fit_bands else None

    def contour_level(self) -> NDArray[np.float64]:
        """(n,) mm, the value contours are printed in increasing order of: the distance
        from the outer loop on a band fitted between two boundaries (outer wall, inwards
        across the band, inner wall last: consecutive lines are neighbours, so they join),
        else the distance from the boundary (outside-in)."""
        sides = self.band_sides()
        return self.geometry.distance if sides is None else sides[0]

    def band_fit_covers(self, spacing: float) -> bool:
        """Whether contours fitted to the band at ``spacing`` leave no hole: at most
        UNCOVERED_SHARE of the area farther than UNCOVERED x spacing from every line.

        The band model (a whole number of lines between the outer loop and the others)
        holds on a wall; where the component is no band (a junction: a solid spot between
        two holes, the aorta's plaque between its lumens) the lines of the two families
        and the medial line can miss whole areas. True without band fitting."""
        if self.band_sides() is None:
            return True
        geo = self.geometry
        hole = geo.line_gap(geo.fitted_contours(spacing)) > UNCOVERED * spacing
        return float(geo.face_area[hole].sum()) <= UNCOVERED_SHARE * geo.face_area.sum()

    def with_band_fit_holes_filled(self, spacing: float) -> LineSource:
        """This source, with eq. 9's iso-lines in the holes of the fitted contours where the
        component is no band (``band_fit_covers`` fails at ``spacing``)."""
        if self.fill_holes or self.band_fit_covers(spacing):
            return self
        return LineSource(self.geometry, self.fit_bands, self.perimeter, True,
                          self.wall_half_width)

    def width_scale(self, pattern: int, spacing: float) -> NDArray[np.float64] | None:
        """(n,) float64, the band's local pitch over ``spacing`` (within
        CENTRE_WIDTH_SCALE) for contours fitted to a band, None for any other lines.

        A band of 4.6 spacings holds 5 lines at 0.92 spacings (``fitted_contours``): the
        lines printed at W x this ratio (the nozzle speed sets it, W = C / (H v)) abut
        instead of overlapping by 8 %, and the band gets the ink its area needs. Not where
        eq. 9's iso-lines fill holes in the fitting (no band there, no pitch), and not on
        stripes: their local spacing 2 pi / |grad psi| is off next to the ends
        trim_converging cuts back."""
        if pattern == PATTERN_STRIPE and self.wall_half_width > 0.0:
            # the walls' centre lines as wide as the wall, the stripes at W
            centre = self.geometry.centre_scale(spacing)
            if centre is None:
                return None
            wall = self.geometry.reach(self.wall_half_width) > self.wall_half_width
            return np.where(wall, centre, 1.0)
        sides = self.band_sides() if pattern == PATTERN_CONTOUR else None
        if sides is None or self.fill_holes:
            return None
        pitch, _ = self.geometry.band_pitch(spacing)
        return np.asarray(np.clip(pitch / spacing, *CENTRE_WIDTH_SCALE), dtype=np.float64)

    def narrow_walls(self, stripes: SurfaceLines) -> SurfaceLines:
        """``stripes`` kept where the component is at least 2 x wall_half_width wide, and
        the centre line along its narrower walls: across a wall about one width wide
        stripes are stubs joined by U-turn connectors, which then lay half the ink, and the
        volume match spreads the stripes of the wide part apart to make up for it (the
        aorta's plaque junction: two tube walls and the bridge between them)."""
        geo, hw = self.geometry, self.wall_half_width
        reach = geo.reach(hw)
        wide = clip_lines(stripes, geo.vertices, geo.faces, -reach, -hw)
        walls = clip_lines(geo.centre_lines(), geo.vertices, geo.faces, reach, hw)
        ident = np.arange(len(geo.faces))
        return merge_lines([walls, wide], [ident, ident])

    def lines(self, pattern: int, spacing: float, poisson: bool = False) -> SurfaceLines:
        """Contours or stripes at ``spacing`` on this surface (its units).

        Contours start half a spacing inside the boundary, or half the largest boundary
        distance where the component is narrower than one spacing (a thin band then still
        gets a loop along its middle).
        """
        geo = self.geometry
        if pattern == PATTERN_CONTOUR:
            if self.band_sides() is not None:
                fitted = geo.fitted_contours(spacing)
                if not self.fill_holes:
                    return fitted
                # where the component is no band, eq. 9's iso-lines of the boundary
                # distance fill the holes the fitted lines leave
                hole = np.flatnonzero(geo.line_gap(fitted) > UNCOVERED * spacing)
                if hole.size == 0:
                    return fitted
                extra = contour_lines(geo.vertices, geo.faces[hole], geo.distance, spacing,
                                      0.5 * spacing)
                return merge_lines([fitted, extra], [np.arange(len(geo.faces)), hole])
            offset = min(0.5 * spacing, 0.5 * geo.max_distance)
            return contour_lines(geo.vertices, geo.faces, geo.distance, spacing, offset)
        fn = poisson_stripe_lines if poisson else stripe_lines
        stripes = fn(geo.vertices, geo.faces, geo.direction, spacing)
        if self.wall_half_width > 0.0:
            return self.narrow_walls(stripes)
        if not self.perimeter or geo.max_distance < PERIMETER_MIN_DISTANCE * spacing:
            return stripes
        loop = perimeter_loop(geo.vertices, geo.faces, geo.distance, spacing)
        inner = clip_lines(stripes, geo.vertices, geo.faces, geo.distance,
                           PERIMETER_CLIP * spacing)
        ident = np.arange(len(geo.faces))
        return merge_lines([loop, inner], [ident, ident])
