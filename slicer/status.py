"""The slicer's status enums: the outcome of each solve and stage, as report.json holds it.

Each is a ``core.status.Status`` (a ``StrEnum`` with a message per member), so a member
compares equal to the string reports have always held. Where a status carries a detail (which
solve failed, and why), the text is the member's value, a colon and the detail
(``with_detail``), exactly as before; code tests the member with ``kind_of``.
"""

from __future__ import annotations

from typing import Self

from core.status import Status


class SolverStatus(Status):
    """A sparse solve (``slicer.solvers.SPDSolver``): its setup or one ``solve`` call."""

    OK = "ok", "solved to the requested residual"
    FALLBACK = "fallback", "set up with another backend after the preferred one failed"
    NOT_CONVERGED = "not_converged", "the iterative solve stopped at its iteration cap"
    FAILED = "failed", "no backend could set up or solve the system; the result is nan"

    def with_detail(self, detail: str) -> str:
        """The status text ``"<value>:<detail>"`` (just the value without a detail)."""
        return f"{self.value}:{detail}" if detail else self.value

    @classmethod
    def kind_of(cls, text: str) -> Self:
        """The member a status text starts with (``"failed:non-finite"`` -> ``FAILED``)."""
        return cls(text.split(":", 1)[0])


class FieldStatus(Status):
    """How the slicing field's iteration ended (``slicer.field.FieldResult.status``)."""

    CONVERGED = "converged", "the alignment O_align changed by less than the convergence threshold"
    MAX_ITERATIONS = "max_iterations", "stopped after max_iterations without converging"
    PLANAR = "planar", "planar slicing: g = z, no iteration"
    NO_ITERATIONS = "no_iterations", "max_iterations = 0: the initial field is the result"
    SOLVER_FAILED = "solver_failed", "a solve failed; g is the last good field"

    def with_detail(self, detail: str) -> str:
        """The status text ``"<value>:<detail>"`` (just the value without a detail)."""
        return f"{self.value}:{detail}" if detail else self.value


class DeformStatus(Status):
    """The constant-width deformation of a component (``slicer.toolpath.deform``)."""

    CONVERGED = "converged", "the relative energy change fell below rtol"
    WITHIN_TOLERANCE = "within_tolerance", "the width spread is within the tolerance"
    MAX_ITERATIONS = "max_iterations", "stopped after the iteration limit"
    SKIPPED = "skipped", "the width is even enough: not deformed"
    FAILED = "failed", "the component's toolpath failed (see its error)"


class VolumeStatus(Status):
    """The volume match of a component's line spacing (``slicer.toolpath.volume``)."""

    CONVERGED = "converged", "the deposited volume is within the tolerance of the required"
    CONVERGED_SCAN = "converged-scan", "within the tolerance, found by scanning the bracket"
    STALLED = "stalled", "the bracket is narrower than the volume's jumps (discrete lines)"
    MAX_ITERATIONS = "max_iterations", "stopped after the iteration limit"
    LIMIT = "limit", "tau reached its limit"
    FAILED = "failed", "the component's toolpath failed (see its error)"


#: suffix of a volume status whose flow per length was fitted afterwards ("stalled+flow")
FLOW_FITTED = "+flow"


class ToolpathStatus(Status):
    """The toolpath stage's verdict (``ToolpathResult.status``, report.json)."""

    OK = "ok", "every component's volume matched within the tolerance"
    VOLUME = "volume", "some component missed the volume tolerance"
    FAILED_COMPONENTS = "failed-components", "some component was skipped (reasons in the report)"


class ComponentFallback(Status):
    """How a layer component was printed instead of its pattern (``ComponentResult.fallback``)."""

    NONE = "", "printed with its layer's pattern"
    CONTOUR = "contour", "a stripe component too narrow for stripes, printed with contours"
    CENTRE_LINE = "centre-line", "a band too narrow for two lines: one line along its middle"
    HOLES_FILLED = "holes-filled", "fitted contours left holes (no band): eq. 9's lines fill them"
    NO_BAND = "no-band", "no band: eq. 9's contours alone kept their spacing better"
    WALLS = "walls", "stripes on the wide part, one line along each narrow wall"
    RIBS = "ribs", "contours on the wide part, one line along each wall too narrow for two"
    TIP = "tip", "too small for any line of its pattern (a tip): one line across it"
