"""Operator notes read from a slice report (slicer/checks.py)."""

from __future__ import annotations

from typing import Any

from slicer.checks import job_notes


def _report(**toolpath: Any) -> dict[str, Any]:
    base: dict[str, Any] = {
        "height_out_of_profile_fraction": 0.0,
        "profile": {"layer_height_range_mm": [0.26, 1.65]},
        "failed_components": {"count": 0, "reasons": []},
        "volume_error": 0.001,
    }
    base.update(toolpath)
    return {"model": {"repairs": []},
            "slicing": {"notes": [], "height_mm": {"min": 0.4, "max": 3.0}},
            "toolpath": base}


def test_a_clean_job_has_no_notes() -> None:
    assert job_notes(_report()) == []
    assert job_notes({}) == []


def test_each_problem_gets_one_line_naming_it_and_a_fix() -> None:
    report = _report(height_out_of_profile_fraction=0.054, volume_error=-0.031,
                     failed_components={"count": 2, "reasons": ["layer 3: ValueError: x"]})
    report["model"]["repairs"] = ["3 duplicate faces removed"]
    report["slicing"]["notes"] = ["critical selector 'top@z>100' kept no patch"]
    notes = job_notes(report)
    assert len(notes) == 5
    assert all("\n" not in n for n in notes)
    assert notes[0] == "model: 3 duplicate faces removed"
    assert notes[1] == "slicing: critical selector 'top@z>100' kept no patch"
    height = notes[2]
    assert "5.4%" in height and "0.26-1.65 mm" in height and "0.40-3.00 mm" in height
    assert "fix:" in height
    assert "2 layer component(s) skipped" in notes[3] and "fix:" in notes[3]
    assert "-3.1%" in notes[4]


def test_small_departures_stay_quiet() -> None:
    assert job_notes(_report(height_out_of_profile_fraction=0.005, volume_error=0.015)) == []
