"""What code reads back from a slice's report.json section, as a typed record."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any


def _number(report: Mapping[str, Any], section: str, key: str) -> float | None:
    value = report.get(section, {}).get(key)
    return None if value is None else float(value)


@dataclass(frozen=True)
class SliceSummary:
    """What code reads back from a slice's report: the numbers ``mesp slice`` prints and the
    runtime's volume check uses (None where the report has no such entry, e.g. ``--until``).

    Attributes:
        layers: number of layers (``slicing.layers``).
        waypoints: number of toolpath waypoints (``toolpath.waypoints``).
        volume_error: deposited / model volume - 1 (``toolpath.volume_error``).
        total_s: wall-clock time of the slice, s (``timing_s.total``).
    """

    layers: int | None
    waypoints: int | None
    volume_error: float | None
    total_s: float | None

    @classmethod
    def of(cls, report: Mapping[str, Any]) -> SliceSummary:
        """The summary of a report dict (``slice_model``'s return, ``read_report``)."""
        layers = report.get("slicing", {}).get("layers")
        waypoints = report.get("toolpath", {}).get("waypoints")
        return cls(layers=None if layers is None else int(layers),
                   waypoints=None if waypoints is None else int(waypoints),
                   volume_error=_number(report, "toolpath", "volume_error"),
                   total_s=_number(report, "timing_s", "total"))

    def as_dict(self) -> dict[str, Any]:
        """Plain values (the line ``mesp slice`` prints)."""
        return asdict(self)
