"""The node adapters: a job planned on the cell gets the plan figures `mesp plan` writes."""

from __future__ import annotations

from pathlib import Path

from mesp_cell.nodes import adapters
from slicer.report import read_report
from tests.planner import synthetic


def test_plan_job_writes_trajectory_and_plan_figures(tmp_path: Path) -> None:
    synthetic.lines(n_lines=2, length=10.0).save(tmp_path)
    report = adapters.plan_job(tmp_path, None)
    assert (tmp_path / "trajectory.npz").is_file()
    names = sorted(Path(p).name for p in report["figures"])
    assert names == ["plan_alpha.png", "plan_clearance.png", "plan_joints.png", "plan_margin.png"]
    for p in report["figures"]:
        assert (tmp_path / p).stat().st_size > 5000
    assert read_report(tmp_path)["plan"]["figures"] == report["figures"]
