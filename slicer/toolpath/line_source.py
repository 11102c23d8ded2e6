"""The line source: contours or stripes of one (possibly deformed) component surface.

``LineSource`` is a ``SurfaceGeometry`` (what is derived from the surface alone, cached)
with the options a component is tried with (band fitting, a stripe perimeter, eq. 9's lines
in the band fit's holes, centre lines along narrow walls): an immutable value, so trying an
option is ``dataclasses.replace(source, option=...)``, which shares the geometry's caches.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from core.stages import Pattern
from slicer.toolpath.contours import contour_lines
from slicer.toolpath.lines import SurfaceLines, merge_lines
from slicer.toolpath.medial import medial_lines, strip_width
from slicer.toolpath.perimeter import (
    PERIMETER_CLIP,
    PERIMETER_MIN_DISTANCE,
    clip_lines,
    perimeter_loop,
)
from slicer.toolpath.poisson_stripes import poisson_stripe_lines
from slicer.toolpath.stripe_width import stripe_width_scale
from slicer.toolpath.surface_geometry import (
    CENTRE_WIDTH_SCALE,
    Backend,
    Sides,
    StripeField,
    SurfaceGeometry,
)

UNCOVERED = 0.8  # band fitting fails where an area is farther than this x spacing from lines
UNCOVERED_SHARE = 0.02  # ... more than this share of the component (eq. 9 lines fill them)


@dataclass(frozen=True, eq=False)
class LineSource:
    """Contours or stripes of one surface with the options a component is tried with.

    Attributes:
        geometry: the surface and its cached derived fields (shared by ``replace``).
        fit_bands: contours of a band (two or more loops) fitted between its sides.
        perimeter: stripes get one loop inside the boundary (``perimeter.py``).
        fill_holes: the fitted contours leave holes (``band_fit_covers``): eq. 9's lines
            fill them.
        wall_half_width: stripes (or contours) only where the component is wider than 2 x
            this, its narrow walls get their centre line (``narrow_walls``, ``ribs``); 0:
            the pattern everywhere.
        fit_ridge: contours that are not fitted to a band get a whole number of lines
            across the component's local width (``ridge_fit.py``) instead of eq. 9's.
        laid_pitch: those lines at the pitch of the count laid where one is dropped for
            room (``ridge_fit._laid_pitch``); False: at the blended pitch everywhere.
    """

    geometry: SurfaceGeometry
    fit_bands: bool = True
    perimeter: bool = False
    fill_holes: bool = False
    wall_half_width: float = 0.0
    fit_ridge: bool = False
    laid_pitch: bool = True

    @staticmethod
    def of(vertices: NDArray[np.float64], faces: NDArray[np.int32], fit_bands: bool = True,
           perimeter: bool = False, distance: Backend = "eikonal",
           stripe_field: StripeField = "across", fit_ridge: bool = False) -> LineSource:
        """The line source of a new surface."""
        return LineSource(SurfaceGeometry(vertices, faces, distance, stripe_field), fit_bands,
                          perimeter, fit_ridge=fit_ridge)

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
                          self.wall_half_width, self.fit_ridge, self.laid_pitch)

    def width_scale(self, pattern: int, spacing: float) -> NDArray[np.float64] | None:
        """(n,) float64, the band's local pitch over ``spacing`` (within
        CENTRE_WIDTH_SCALE) for contours fitted to a band, the stripes' spacing to their
        neighbours over ``spacing`` (``stripe_width``) for stripes without a perimeter
        loop, None for any other lines.

        A band of 4.6 spacings holds 5 lines at 0.92 spacings (``fitted_contours``): the
        lines printed at W x this ratio (the nozzle speed sets it, W = C / (H v)) abut
        instead of overlapping by 8 %, and the band gets the ink its area needs. Not where
        eq. 9's iso-lines fill holes in the fitting (no band there, no pitch). Stripes
        fanning out across a disc spread up to 2x between branch points: each is printed
        as wide as the gaps to the stripes beside it (measured between the lines, not the
        field's 2 pi / |grad psi|, which is off next to the ends trim_converging cuts)."""
        geo = self.geometry
        loop = self.perimeter and geo.max_distance >= PERIMETER_MIN_DISTANCE * spacing
        if pattern == Pattern.STRIPE and self.wall_half_width == 0.0 and not loop:
            # stripes as wide as their local spacing (``stripe_width``)
            return stripe_width_scale(geo.vertices, geo.faces, geo.stripes(spacing),
                                      geo.distance, spacing)
        if pattern == Pattern.STRIPE and self.wall_half_width > 0.0:
            # the walls' centre lines as wide as the wall, the stripes at W
            centre = self.geometry.centre_scale(spacing)
            if centre is None:
                return None
            wall = self.geometry.reach(self.wall_half_width) > self.wall_half_width
            return np.where(wall, centre, 1.0)
        if pattern == Pattern.CONTOUR and self.wall_half_width > 0.0:
            # the walls' medial lines as wide as the wall, the contours as without walls
            rib = self.centre_scale(spacing)
            base = replace(self, wall_half_width=0.0).width_scale(pattern, spacing)
            if rib is None:
                return base
            wall = self.geometry.reach(self.wall_half_width) > self.wall_half_width
            return np.where(wall, rib, 1.0 if base is None else base)
        if self._ridge_fitted(pattern):
            pitch = self.geometry.ridge_fit(spacing, self.laid_pitch)[1]
            return np.asarray(np.clip(pitch / spacing, *CENTRE_WIDTH_SCALE), dtype=np.float64)
        sides = self.band_sides() if pattern == Pattern.CONTOUR else None
        if sides is None or self.fill_holes:
            return None
        pitch, _ = self.geometry.band_pitch(spacing)
        return np.asarray(np.clip(pitch / spacing, *CENTRE_WIDTH_SCALE), dtype=np.float64)

    def _ridge_fitted(self, pattern: int) -> bool:
        """Contours fitted to the local width (``fit_ridge``): where they are not fitted
        to a band between two sides, or that fit leaves holes."""
        return (pattern == Pattern.CONTOUR and self.fit_ridge
                and (self.band_sides() is None or self.fill_holes))

    def laid_pitch_matters(self, spacing: float) -> bool:
        """Whether the contours fitted to the local width at ``spacing`` change with
        ``laid_pitch`` (a line is dropped for room somewhere): only then is the other pitch
        worth a try."""
        geo = self.geometry
        return not np.array_equal(geo.ridge_fit(spacing, True)[1],
                                  geo.ridge_fit(spacing, False)[1])

    def centre_lines(self) -> SurfaceLines:
        """One line along the middle of a component about one width wide: between its two
        sides on a band with one hole (``SurfaceGeometry.centre_lines``), else its medial
        line (``medial.medial_lines``: a strip without holes, walls between many holes)."""
        geo = self.geometry
        if geo.loops == 2:
            return geo.centre_lines()
        return medial_lines(geo.vertices, geo.faces)

    def centre_scale(self, spacing: float) -> NDArray[np.float64] | None:
        """(n,) float64, the local width of the strip over ``spacing`` (within
        CENTRE_WIDTH_SCALE), the width its centre line prints at (``centre_lines``)."""
        geo = self.geometry
        if geo.loops == 2:
            return geo.centre_scale(spacing)
        width = strip_width(geo.vertices, geo.faces, self.centre_lines())
        if not np.isfinite(width).all():
            return None
        return np.asarray(np.clip(width / spacing, *CENTRE_WIDTH_SCALE), dtype=np.float64)

    def narrow_walls(self, stripes: SurfaceLines) -> SurfaceLines:
        """``stripes`` kept where the component is at least 2 x wall_half_width wide, and
        the centre line along its narrower walls: across a wall about one width wide
        stripes are stubs joined by U-turn connectors, which then lay half the ink, and the
        volume match spreads the stripes of the wide part apart to make up for it (the
        aorta's plaque junction: two tube walls and the bridge between them)."""
        return self._wide_and_walls(stripes, self.geometry.centre_lines())

    def ribs(self, contours: SurfaceLines) -> SurfaceLines:
        """``contours`` kept where the component is at least 2 x wall_half_width wide, and
        the medial line along its narrower walls (``centre_lines``): a rib narrower than
        about 1.5 W between two holes holds one line, not a ring from each hole (two lines
        a rib's width apart) nor none (the rim's rings only, the ribs' ink laid there;
        the octagonal pocket's honeycomb)."""
        return self._wide_and_walls(contours, self.centre_lines())

    def _wide_and_walls(self, lines: SurfaceLines, centre: SurfaceLines) -> SurfaceLines:
        """``lines`` where the component is at least 2 x wall_half_width wide, ``centre``
        where it is narrower."""
        geo, hw = self.geometry, self.wall_half_width
        reach = geo.reach(hw)
        wide = clip_lines(lines, geo.vertices, geo.faces, -reach, -hw)
        walls = clip_lines(centre, geo.vertices, geo.faces, reach, hw)
        ident = np.arange(len(geo.faces))
        return merge_lines([walls, wide], [ident, ident])

    def lines(self, pattern: int, spacing: float, poisson: bool = False) -> SurfaceLines:
        """Contours or stripes at ``spacing`` on this surface (its units).

        Contours start half a spacing inside the boundary, or half the largest boundary
        distance where the component is narrower than one spacing (a thin band then still
        gets a loop along its middle).
        """
        geo = self.geometry
        if pattern == Pattern.CONTOUR and self.wall_half_width > 0.0:
            return self.ribs(replace(self, wall_half_width=0.0).lines(pattern, spacing))
        if self._ridge_fitted(pattern):
            return geo.ridge_fit(spacing, self.laid_pitch)[0]
        if pattern == Pattern.CONTOUR:
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
        stripes = (poisson_stripe_lines(geo.vertices, geo.faces, geo.direction, spacing)
                   if poisson else geo.stripes(spacing))
        if self.wall_half_width > 0.0:
            return self.narrow_walls(stripes)
        if not self.perimeter or geo.max_distance < PERIMETER_MIN_DISTANCE * spacing:
            return stripes
        loop = perimeter_loop(geo.vertices, geo.faces, geo.distance, spacing)
        inner = clip_lines(stripes, geo.vertices, geo.faces, geo.distance,
                           PERIMETER_CLIP * spacing)
        ident = np.arange(len(geo.faces))
        return merge_lines([loop, inner], [ident, ident])
