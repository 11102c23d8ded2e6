"""One component surface and what the line generators derive from it alone: boundary
distance, the distances from the outer loop and from the others, the stripe direction, the
band's pitch, its centre line. Each is computed on first use and then kept (cached
properties; per-argument values keep the last one asked for), so the line sources that share
a geometry (``line_source.LineSource`` with other options) compute it once.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import Literal

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from core.tolerance import tol
from slicer.toolpath.contours import band_pitch, two_sided_contour_lines
from slicer.toolpath.eikonal import points_to_segments
from slicer.toolpath.geodesic import boundary_distance, distance_from
from slicer.toolpath.isolines import iso_lines
from slicer.toolpath.lines import SurfaceLines, empty_lines
from slicer.toolpath.medial import medial_lines
from slicer.toolpath.ridge_fit import band_across, ridge_fitted_lines
from slicer.toolpath.stripes import stripe_lines
from slicer.toolpath.surface import (
    boundary_loops,
    cotan_laplacian,
    face_normals,
    lumped_mass,
    parallel_direction,
    spd_solver,
    stripe_direction,
)

PITCH_SMOOTHING = 2.0  # contour pitch blended over this x W where the line count changes
CENTRE_WIDTH_SCALE = (0.5, 1.5)  # a line's width may be scaled by the nozzle speed this far

Backend = Literal["eikonal", "heat"]
StripeField = Literal["across", "parallel"]
Sides = tuple[NDArray[np.float64], NDArray[np.float64]]
PitchFit = tuple[NDArray[np.float64], NDArray[np.float64]]


@dataclass(frozen=True, eq=False)
class SurfaceGeometry:
    """One component surface and what is derived from it alone (cached on first use).

    Attributes:
        vertices: (n, 3) float64, surface units (mm, or deformed mm).
        faces: (m, 3) int32.
        backend: boundary distance solver (``geodesic.boundary_distance``).
        stripe_field: the stripes' direction on a component with one boundary loop:
            'across' the contours (eq. 11), or 'parallel' (``surface.parallel_direction``).
    """

    vertices: NDArray[np.float64]
    faces: NDArray[np.int32]
    backend: Backend = "eikonal"
    stripe_field: StripeField = "across"
    # the last value asked for per argument (a volume match asks for one spacing twice in a
    # row: the coverage check, then its first trial); the smoother: the first one
    _reach: dict[float, NDArray[np.float64]] = field(default_factory=dict, repr=False)
    _fitted: dict[float, SurfaceLines] = field(default_factory=dict, repr=False)
    _pitch: dict[float, PitchFit] = field(default_factory=dict, repr=False)
    _stripes: dict[float, SurfaceLines] = field(default_factory=dict, repr=False)
    _smoother: list[Callable[[NDArray[np.float64]], NDArray[np.float64]]] = field(
        default_factory=list, repr=False)
    _ridge_fit: dict[tuple[float, bool], tuple[SurfaceLines, NDArray[np.float64]]] = field(
        default_factory=dict, repr=False)

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
        """(m, 3) float64, unit per-face stripe direction: across the contours
        (``surface.stripe_direction``, eq. 11), or with ``stripe_field`` 'parallel' on a
        component with one boundary loop parallel stripes (``surface.parallel_direction``)."""
        if self.stripe_field == "parallel" and self.loops == 1:
            parallel = parallel_direction(self.vertices, self.faces)
            if parallel is not None:
                return parallel
        return stripe_direction(self.vertices, self.faces, self.distance)

    @cached_property
    def loops(self) -> int:
        """Number of boundary loops."""
        return len(boundary_loops(self.faces))

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

    def stripes(self, spacing: float) -> SurfaceLines:
        """Stripes along ``direction`` at ``spacing`` (``stripes.stripe_lines``): the lines
        and the widths they print at (``stripe_width``) are both taken from them."""
        if spacing not in self._stripes:
            lines = stripe_lines(self.vertices, self.faces, self.direction, spacing)
            self._stripes.clear()
            self._stripes[spacing] = lines
        return self._stripes[spacing]

    @cached_property
    def band_across(self) -> NDArray[np.float64]:
        """(n,) float64, the component's width across each vertex (``ridge_fit.band_across``)."""
        return band_across(self.vertices, self.faces, self.distance)

    @cached_property
    def ridge(self) -> SurfaceLines:
        """Where fronts from different stretches of the boundary meet (the medial line,
        ``medial.medial_lines``)."""
        return medial_lines(self.vertices, self.faces)

    def ridge_fit(self, spacing: float, laid: bool = True
                  ) -> tuple[SurfaceLines, NDArray[np.float64]]:
        """``ridge_fit.ridge_fitted_lines`` at ``spacing``, the pitch blended over
        PITCH_SMOOTHING spacings (``laid``: that of the lines laid where one is dropped for
        room): the lines and (n,) their local pitch."""
        key = (spacing, laid)
        if key not in self._ridge_fit:
            smooth = self.smoother(PITCH_SMOOTHING * spacing) if PITCH_SMOOTHING > 0 else None
            fit = ridge_fitted_lines(self.vertices, self.faces, self.distance,
                                     self.band_across, spacing, smooth, ridge=self.ridge,
                                     laid=laid)
            if len(self._ridge_fit) >= 2:
                self._ridge_fit.clear()
            self._ridge_fit[key] = fit
        return self._ridge_fit[key]

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
