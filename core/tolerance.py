"""One tolerance object for the whole pipeline (in the spirit of ``trimesh.tol``)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Tolerance:
    """Numerical tolerances, in the units named per field.

    Attributes:
        zero: float, below this a length or area (mm, mm^2) is treated as zero; also the
            floor a divisor (a length, a time step, a speed) is clamped to.
        merge: float, mm, vertices closer than this are the same point.
        unit: float, |norm - 1| below this counts as a unit vector.
        iso: float, relative offset keeping iso-values off mesh vertices.
        solver: float, relative residual accepted from iterative sparse solvers.
        slack: float, slack of a float comparison against a limit, absolute (mm, deg, s, a
            cosine) or relative to the limit, so a value exactly on the limit is not refused
            by rounding.
        floor: float, a derived quantity (a step, spacing, speed or angle: mm, mm/s, s, rad)
            below this counts as zero, and a divisor made of one is clamped to it; coarser
            than ``zero`` because such values carry the rounding of the arithmetic that made
            them.
        still: float, mm, rad or s, a step, joint change, axis turn or time step below this
            is no motion (a repeated waypoint or pose).
        tiny: float, the smallest divisor: a sum, area or length that may be exactly zero is
            clamped to it before dividing, which changes no value that is not zero.
        computed: float, relative (or mm) accuracy of a value computed by a factorisation or
            an iteration: a probe solve, a clearance or a recurrence's end point within this
            of its target agrees with it.
        singular: float, a sine below this is a singular configuration (the UR wrist at 0 or
            180 deg): the angle that would be divided by it is taken as 0.
        direction: float, a vector shorter than this has no direction; normalising it
            divides by 1 instead.
        parallel: float, a cross product shorter than this, relative to the vectors'
            lengths, makes two directions parallel.
        edge_on: float, mm^2, twice a triangle's projected area below this: the triangle is
            seen edge-on (a ray grazes it).
        on_surface: float, relative to the part's size, a point within this of a face lies
            on it.
    """

    zero: float = 1e-12
    merge: float = 1e-8
    unit: float = 1e-6
    iso: float = 1e-9
    solver: float = 1e-10
    slack: float = 1e-9
    floor: float = 1e-9
    still: float = 1e-6
    computed: float = 1e-6
    tiny: float = 1e-300
    singular: float = 1e-10
    direction: float = 1e-15
    parallel: float = 1e-6
    edge_on: float = 1e-14
    on_surface: float = 1e-7


tol = Tolerance()
