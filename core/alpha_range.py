"""The printing-angle range the cell allows, as the slicer's step limits need it.

The nozzle prints along -normal with the printing angle alpha (between the nozzle axis and the
direction of motion) inside the cell's range (paper section 3.1: [70, 110] deg). The range is a
cell setting: it lives in the cell file (``[planning] alpha_min_deg``, ``alpha_max_deg``), the
planner enforces it, and the slicer receives it (``mesp slice --cell``, the job's cell in the
runtime) to keep its paths printable: a step that leaves the plane normal to its waypoint's
printing direction by more than ``step_elevation_deg`` cannot be printed within the range.
"""

from __future__ import annotations

from dataclasses import dataclass

from core.toml_defaults import table

# Flushing moves may tilt a step by at most this fraction of the range's step elevation: the
# planner keeps alpha within range against both ends of a step, and a flushed step's end
# waypoints may already lean (20 deg range -> 14 deg, the aorta's diving tread).
FLUSH_STEP_FRACTION = 0.7


@dataclass(frozen=True)
class AlphaRange:
    """alpha in [min_deg, max_deg], deg, around 90 (perpendicular to the motion)."""

    min_deg: float
    max_deg: float

    def __post_init__(self) -> None:
        if not 0 <= self.min_deg <= 90 <= self.max_deg <= 180:
            raise ValueError("need 0 <= alpha_min_deg <= 90 <= alpha_max_deg <= 180")

    @staticmethod
    def bundled() -> AlphaRange:
        """The range of the bundled cell (``planner/cells/default.toml``)."""
        planning = table("planner", "cells/default.toml", "planning")
        return AlphaRange(float(planning["alpha_min_deg"]), float(planning["alpha_max_deg"]))

    @property
    def step_elevation_deg(self) -> float:
        """deg, the steepest step out of the layer a nozzle in range still follows."""
        return min(90.0 - self.min_deg, self.max_deg - 90.0)

    @property
    def flush_step_deg(self) -> float:
        """deg, the steepest step flushing may make (``FLUSH_STEP_FRACTION`` of the above)."""
        return FLUSH_STEP_FRACTION * self.step_elevation_deg
