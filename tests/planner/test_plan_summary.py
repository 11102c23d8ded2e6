"""planner.plan_summary: the record code reads from a plan's report section."""

from __future__ import annotations

import json
import math

from planner.plan_summary import PlanSummary
from planner.status import PlanStatus

SECTION = {"status": "unreachable waypoints", "duration_s": 12.3456, "min_clearance_mm": 7.5,
           "unreachable": {"count": 3, "by_reason": {}}, "tolerance_mm": 0.1,
           "over_deposition": {"volume_mm3": 1.23456, "fraction": 0.01}}


def test_the_summary_reads_the_report_section_and_prints_the_done_line() -> None:
    s = PlanSummary.of(SECTION)
    assert s.status is PlanStatus.UNREACHABLE and s.unreachable == 3
    assert s.to_dict() == {"status": "unreachable waypoints", "duration_s": 12.35,
                           "min_clearance_mm": 7.5, "unreachable": 3,
                           "over_deposition_mm3": 1.235}


def test_to_dict_and_from_dict_round_trip_through_json() -> None:
    s = PlanSummary.of({**SECTION, "min_clearance_mm": None})
    back = PlanSummary.from_dict(json.loads(json.dumps(s.to_dict())))
    assert back.to_dict() == s.to_dict() and back.min_clearance_mm is None


def test_a_section_without_a_status_counts_as_ok_with_unknown_numbers() -> None:
    s = PlanSummary.of({})
    assert s.status is PlanStatus.OK and math.isnan(s.duration_s) and s.unreachable == 0
