"""Job bundles: the report, figures, preview and telemetry in one zip; npz stages left out."""

from __future__ import annotations

import zipfile
from pathlib import Path

import pytest

from core.errors import InputError
from mesp_cell.bundle import bundle_job


def test_bundle_holds_what_a_reviewer_needs(tmp_path: Path) -> None:
    job = tmp_path / "job"
    (job / "figures").mkdir(parents=True)
    for name in ("report.json", "preview.html", "telemetry.mcap", "telemetry-2.mcap",
                 "figures/plan_joints.png", "figures/dry_run.mp4", "inspect_ct.png",
                 "toolpath.npz", "trajectory.npz"):
        (job / name).write_bytes(b"x" * 100)
    out, files = bundle_job(job, tmp_path / "out" / "job.zip")
    with zipfile.ZipFile(out) as z:
        names = set(z.namelist())
        assert z.testzip() is None
    assert names == {"report.json", "preview.html", "telemetry.mcap", "telemetry-2.mcap",
                     "figures/plan_joints.png", "figures/dry_run.mp4", "inspect_ct.png"}
    assert len(files) == 7 and not (tmp_path / "out" / "job.zip.part").exists()


def test_missing_or_empty_job_is_a_user_error(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="does not exist"):
        bundle_job(tmp_path / "nope", tmp_path / "x.zip")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="holds no report"):
        bundle_job(tmp_path / "empty", tmp_path / "x.zip")
