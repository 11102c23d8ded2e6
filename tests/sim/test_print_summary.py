"""sim.print_summary: the record the inspect table and the comparison read from a summary."""

from __future__ import annotations

import json
import math

from sim.pipeline import comparison
from sim.print_summary import PrintSummary

SUMMARY = {"infill_ratio": 0.98, "interior_infill_ratio": 0.995, "interior_depth_mm": 1.0,
           "pore_ratio": 0.002, "over_deposition": 0.03, "under_deposition": 0.02,
           "surface_error_mm": {"mean": 0.2, "p95": 0.5, "max": 1.1},
           "surface_error_by_facing": {"up": {"share": 0.4, "signed_mean": 0.05},
                                       "down": {"share": 0.0, "signed_mean": 0.0}},
           "deposition_status": "ok", "waypoints": 12}


def test_the_record_reads_its_entries_and_writes_them_back_under_the_same_keys() -> None:
    s = PrintSummary.from_dict(SUMMARY)
    assert s.infill_ratio == 0.98 and s.surface_error_mm["p95"] == 0.5
    back = json.loads(json.dumps(s.to_dict()))
    assert back == {k: v for k, v in SUMMARY.items() if k in back}
    assert "waypoints" not in back and PrintSummary.from_dict(back) == s


def test_signed_error_is_nan_where_no_face_faces_that_way() -> None:
    s = PrintSummary.from_dict(SUMMARY)
    assert s.signed_error("up") == 0.05
    assert math.isnan(s.signed_error("down")) and math.isnan(s.signed_error("side"))


def test_the_comparison_puts_the_two_prints_beside_the_paper() -> None:
    main = PrintSummary.from_dict(SUMMARY)
    base = PrintSummary.from_dict({**SUMMARY, "infill_ratio": 0.9})
    out = comparison(main, base)
    assert out["infill_ratio"] == {"multi_axis": 0.98, "baseline": 0.9}
    assert out["surface_error_mean_mm"]["paper_planar"] == 0.49
