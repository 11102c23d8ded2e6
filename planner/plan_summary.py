"""What code reads back from a plan's report section, as a typed record.

``mesp plan`` prints it as its ``done:`` line; ``mesp export`` refuses a trajectory whose
status is not OK; ``mesp demo`` shows its duration. They read it from report.json's ``plan``
section (``of``), so a job planned earlier reads the same. ``to_dict`` is the JSON the
``done:`` line has always printed and ``from_dict`` reads it back.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from planner.status import PlanStatus


@dataclass(frozen=True)
class PlanSummary:
    """A plan's verdict and the numbers an operator is shown first.

    Attributes:
        status: the plan's verdict (only ``PlanStatus.OK`` may be executed).
        duration_s: float, s, the trajectory's duration (nan where the section has none).
        min_clearance_mm: float, mm, the smallest clearance to the cell on the executed
            motion (None where it was not computed).
        unreachable: int, toolpath waypoints without a pose within the limits.
        over_deposition_mm3: float, mm^3, ink laid where the nozzle runs slower than asked.
    """

    status: PlanStatus
    duration_s: float
    min_clearance_mm: float | None
    unreachable: int
    over_deposition_mm3: float

    @classmethod
    def of(cls, plan: Mapping[str, Any]) -> PlanSummary:
        """The summary of a report's ``plan`` section (``PlanResult.report``, report.json);
        a section without a status counts as OK, missing numbers are nan or 0."""
        clearance = plan.get("min_clearance_mm")
        return cls(status=PlanStatus(plan.get("status", PlanStatus.OK)),
                   duration_s=float(plan.get("duration_s", float("nan"))),
                   min_clearance_mm=None if clearance is None else float(clearance),
                   unreachable=int(plan.get("unreachable", {}).get("count", 0)),
                   over_deposition_mm3=float(
                       plan.get("over_deposition", {}).get("volume_mm3", 0.0)))

    def to_dict(self) -> dict[str, Any]:
        """The JSON ``mesp plan`` prints (duration to 0.01 s, over-deposition to 0.001 mm^3)."""
        return {"status": str(self.status), "duration_s": round(self.duration_s, 2),
                "min_clearance_mm": self.min_clearance_mm, "unreachable": self.unreachable,
                "over_deposition_mm3": round(self.over_deposition_mm3, 3)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> PlanSummary:
        """The summary ``to_dict`` wrote (the ``done:`` line's JSON)."""
        clearance = data["min_clearance_mm"]
        return cls(status=PlanStatus(data["status"]), duration_s=float(data["duration_s"]),
                   min_clearance_mm=None if clearance is None else float(clearance),
                   unreachable=int(data["unreachable"]),
                   over_deposition_mm3=float(data["over_deposition_mm3"]))
