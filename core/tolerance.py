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
        slack: float, absolute slack of a float comparison against a limit (mm, deg, a
            cosine), so a value exactly on the limit is not refused by rounding.
    """

    zero: float = 1e-12
    merge: float = 1e-8
    unit: float = 1e-6
    iso: float = 1e-9
    solver: float = 1e-10
    slack: float = 1e-9


tol = Tolerance()
