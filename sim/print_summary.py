"""What code reads back from a simulated print's report summary, as a typed record.

``mesp inspect``'s side-by-side table and the report's ``comparison`` with the paper read the
quality of each simulated print (the multi-axis print, as planned, the baselines) from the
summary ``sim.metrics.Quality.summary`` writes into report.json. ``PrintSummary.from_dict``
reads those entries of a summary (its other entries are ignored), ``to_dict`` writes them
back under the same keys, so a summary read from an earlier report.json reads the same.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

FACINGS = ("up", "side", "down")


@dataclass(frozen=True)
class PrintSummary:
    """The quality of one simulated print against the model (ratios are of the model volume).

    Attributes:
        infill_ratio: float, share of the model volume filled.
        interior_infill_ratio: float, the same below ``interior_depth_mm`` of the surface.
        pore_ratio: float, enclosed voids over the model volume.
        over_deposition: float, material outside the model over the model volume.
        under_deposition: float, model volume left empty over the model volume.
        surface_error_mm: statistics of the surface error, mm (``mean``, ``p95``, ``max``...).
        surface_error_by_facing: per facing (``up``, ``side``, ``down``): its ``share`` of the
            model surface and its ``signed_mean`` error, mm (> 0 the print bulges out).
    """

    infill_ratio: float
    interior_infill_ratio: float
    pore_ratio: float
    over_deposition: float
    under_deposition: float
    surface_error_mm: Mapping[str, float]
    surface_error_by_facing: Mapping[str, Mapping[str, float]]

    def signed_error(self, facing: str) -> float:
        """Signed mean surface error on the faces facing ``facing``, mm (nan if none)."""
        part = self.surface_error_by_facing.get(facing)
        return float(part["signed_mean"]) if part and part["share"] > 0 else float("nan")

    def to_dict(self) -> dict[str, Any]:
        """These entries of the report's summary, under its keys."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_dict(cls, summary: Mapping[str, Any]) -> PrintSummary:
        """The record of a report summary (``Quality.summary``, report.json's ``inspect``)."""
        return cls(**{f.name: summary[f.name] for f in fields(cls)})
