"""The slice summary reads the report's numbers as typed values."""

from __future__ import annotations

from slicer.summary import SliceSummary


def test_a_full_report_gives_typed_numbers() -> None:
    report = {"slicing": {"layers": 12}, "toolpath": {"waypoints": 3400, "volume_error": -0.01},
              "timing_s": {"total": 8}}
    summary = SliceSummary.of(report)
    assert summary == SliceSummary(layers=12, waypoints=3400, volume_error=-0.01, total_s=8.0)
    assert isinstance(summary.total_s, float)
    assert summary.as_dict() == {"layers": 12, "waypoints": 3400, "volume_error": -0.01,
                                 "total_s": 8.0}


def test_a_partial_report_gives_none() -> None:
    # mesp slice --until field: no toolpath section yet
    summary = SliceSummary.of({"slicing": {"layers": 5}})
    assert summary == SliceSummary(layers=5, waypoints=None, volume_error=None, total_s=None)
