"""Operator notes read from a slice report (slicer/checks.py)."""

from __future__ import annotations

from typing import Any

from slicer.checks import critical_line, job_notes


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


def test_downward_directions_get_a_note_whose_fix_fits_the_selectors() -> None:
    report = _report(printing_direction={"downward": 12, "max_from_up_deg": 150.0,
                                         "downward_layers": [40, 41]})
    report["job"] = {"config": {"slicing": {"critical": ["bottom:45", "top:45"]}}}
    (note,) = job_notes(report)
    assert "12 extruding waypoints print downward" in note
    assert "--critical bottom:45" in note
    report["job"]["config"]["slicing"]["critical"] = ["bottom:45@end"]
    (note,) = job_notes(report)
    assert "rotate the model" in note


def test_coverage_beyond_its_limits_gets_a_note() -> None:
    fine = _report(coverage={"contour": {"gap": 0.02, "overlap": 0.01},
                             "stripe": {"gap": 0.04, "overlap": 0.03}})
    assert job_notes(fine) == []
    bad = _report(coverage={"contour": {"gap": 0.06, "overlap": 0.01},
                            "stripe": {"gap": None, "overlap": None}})
    (note,) = job_notes(bad)
    assert note.startswith("toolpath: contour layers leave 6.0%")


def test_the_critical_line_names_each_selectors_regions() -> None:
    report = {"slicing": {"critical_regions": [
        {"selector": "bottom:45@end", "area_mm2": 412.3},
        {"selector": "top:30", "area_mm2": 80.0}, {"selector": "top:30", "area_mm2": 20.0}]}}
    assert critical_line(report) == ("critical surfaces: bottom:45@end: 1 region(s) of 412 "
                                     "mm^2; top:30: 2 region(s) of 80, 20 mm^2")
    assert critical_line({}) is None
    assert "none" in str(critical_line({"slicing": {"critical_regions": []}}))


def test_too_much_ink_at_the_narrowest_width_names_thin_walls() -> None:
    # a 0.2 mm tube wall (trimesh's round.stl at 40 mm): the centre line at half its W still
    # lays 5.7x the ink
    report = _report(volume_error=4.7, width_over_profile={"min": 0.5})
    (note,) = job_notes(report)
    assert "thinner than the narrowest filament" in note and "--scale-to" in note
    wide = _report(volume_error=0.05, width_over_profile={"min": 0.8})
    (note,) = job_notes(wide)
    assert "see toolpath.per_layer" in note


def test_walls_printed_thicker_than_the_model_are_noted_with_their_layers() -> None:
    # thin_walls = "thicken": the tube at 40 mm printed anyway
    thin = {"excess_share": 0.45, "limit": 0.01, "wall_mm": 0.58, "line_mm": 1.15,
            "layers": [[1, 9.0], [6, 8.1]], "fits_at_size_mm": 100.0}
    (note,) = job_notes(_report(volume_error=0.45, too_thin=thin))
    assert "walls about 0.58 mm thick print at the narrowest line (1.15 mm)" in note
    assert "2 layer(s) (1-6)" in note and "--scale-to 100" in note
    too_big = dict(thin, too_big="265 mm tall, it would stand out of the gel (240 mm)")
    (note,) = job_notes(_report(volume_error=0.45, too_thin=too_big))
    assert note.endswith("fix: a profile with a finer nozzle (at --scale-to 100, 265 mm tall, "
                         "it would stand out of the gel (240 mm))")
    small = dict(thin, excess_share=0.004)
    assert job_notes(_report(too_thin=small)) == []


def test_direction_jumps_get_a_note_with_what_the_planners_bend_test_found() -> None:
    jumps = {"downward": 0, "jumps": 7, "max_jump_deg": 48.2, "jump_layers": [3, 9]}
    (note,) = job_notes(_report(printing_direction=jumps))
    assert "7 neighbouring extruding waypoints turn" in note and "up to 48 deg" in note
    assert "layers 3, 9" in note
    report = _report(printing_direction=jumps)
    report["printability"] = {"alpha_range_deg": [70.0, 110.0], "refused_waypoints": 0}
    (note,) = job_notes(report)
    assert "keeps alpha in [70, 110] deg at every waypoint" in note
    report["printability"] = {"alpha_range_deg": [70.0, 110.0], "refused_waypoints": 3,
                              "note": "3 waypoints cannot be printed ...; fix: re-slice"}
    jump, plan = job_notes(report)
    assert "cannot follow some of them (see the plan note)" in jump
    assert plan == "plan: 3 waypoints cannot be printed ...; fix: re-slice"
