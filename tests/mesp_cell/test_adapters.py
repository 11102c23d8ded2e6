"""The node adapters: a job planned on the cell gets the plan figures `mesp plan` writes."""

from __future__ import annotations

from pathlib import Path

import pytest

from core.report import read_report
from mesp_cell.nodes import adapters
from tests.planner import synthetic

ROOT = Path(__file__).resolve().parents[2]


def test_plan_job_writes_trajectory_and_plan_figures(tmp_path: Path) -> None:
    synthetic.lines(n_lines=2, length=10.0).save(tmp_path)
    report = adapters.plan_job(tmp_path, None)
    assert (tmp_path / "trajectory.npz").is_file()
    names = sorted(Path(p).name for p in report["figures"])
    assert names == ["plan_alpha.png", "plan_clearance.png", "plan_joints.png", "plan_margin.png"]
    for p in report["figures"]:
        assert (tmp_path / p).stat().st_size > 5000
    assert read_report(tmp_path)["plan"]["figures"] == report["figures"]


def test_a_slice_off_the_models_volume_is_refused_before_planning(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # trimesh's round.stl at 40 mm: a 0.2 mm tube wall, +470 % of the ink even at the
    # narrowest width; the cell must not print it
    from core.errors import InputError
    from slicer import pipeline

    model = tmp_path / "m.stl"
    model.write_bytes(b"solid m\nendsolid m\n")

    def fake(error: float) -> object:
        def slice_model(*args: object, **kw: object) -> dict[str, object]:
            return {"toolpath": {"volume_error": error, "width_over_profile": {"min": 0.5}}}
        return slice_model

    monkeypatch.setattr(pipeline, "slice_model", fake(4.7))
    with pytest.raises(InputError) as refused:
        adapters.slice_job(model, None, tmp_path / "job", "sim")
    assert "+470.0%" in refused.value.problem and "--scale-to" in refused.value.fix
    monkeypatch.setattr(pipeline, "slice_model", fake(0.004))
    assert adapters.slice_job(model, None, tmp_path / "job", "sim")["toolpath"]


def test_a_jobs_cell_sets_the_slicers_alpha_range_and_path_accelerations(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The runtime's slicer node slices for the cell file the job was submitted with."""
    from core.alpha_range import AlphaRange
    from core.path_accel import PathAccel
    from slicer import pipeline

    cell = tmp_path / "cell.toml"
    cell.write_text("[planning]\nalpha_min_deg = 75.0\npath_accel_mm_s2 = 35.0\n"
                    "path_turn_accel_rad_s2 = 0.75\n")
    seen: dict[str, object] = {}

    def spy(*args: object, **kw: object) -> dict[str, object]:
        seen.update(kw)
        return {}

    monkeypatch.setattr(pipeline, "slice_model", spy)
    adapters.slice_job(ROOT / "examples" / "cube.stl", None, tmp_path / "job", "sim", cell)
    assert seen["accel"] == PathAccel(35.0, 0.75)
    assert seen["alpha"] == AlphaRange(75.0, 110.0)
