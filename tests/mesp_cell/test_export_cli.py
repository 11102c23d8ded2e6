"""`mesp export`: the three formats written, user mistakes as one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from core.report import update_report
from mesp_cell.cli import main
from planner.cell import load_cell
from planner.plan import plan
from slicer.extrusion import PROFILE_FILE, load_profile
from tests.planner import synthetic


@pytest.fixture(scope="module")
def job(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("job")
    tp = synthetic.lines(n_lines=2, length=10.0)
    tp.save(out)
    load_profile("ecoflex-0030").save_to_job(out)  # as mesp slice records it
    result = plan(tp, load_cell())
    result.trajectory.save(out)
    update_report(out, {"plan": {"status": result.report["status"]}})
    return out


def test_each_format_is_written(job: Path) -> None:
    for fmt, name in (("printpoints", "printpoints.json"), ("csv", "waypoints.csv"),
                      ("urscript", "print.script")):
        assert main(["export", str(job), "--format", fmt]) == 0
        assert (job / "export" / name).stat().st_size > 100
    assert len(json.loads((job / "export" / "printpoints.json").read_text())) > 10
    assert "servoj(" in (job / "export" / "print.script").read_text()


def test_missing_stage_and_refused_plan_are_one_line_errors(
        job: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["export", str(tmp_path), "--format", "csv"]) == 2
    assert "run `mesp slice" in capsys.readouterr().err
    (tmp_path / "toolpath.npz").write_bytes((job / "toolpath.npz").read_bytes())
    assert main(["export", str(tmp_path), "--format", "urscript"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("mesp: error:") and "mesp plan" in err and len(err.splitlines()) == 1
    (tmp_path / "trajectory.npz").write_bytes((job / "trajectory.npz").read_bytes())
    update_report(tmp_path, {"plan": {"status": "unreachable waypoints"}})
    assert main(["export", str(tmp_path), "--format", "urscript"]) == 2
    assert "cannot be executed" in capsys.readouterr().err
    update_report(tmp_path, {"plan": {"status": "ok"}})
    assert main(["export", str(tmp_path), "--format", "urscript"]) == 2
    assert "re-slice" in capsys.readouterr().err  # no profile recorded: no set-point to send
    (tmp_path / PROFILE_FILE).write_bytes((job / PROFILE_FILE).read_bytes())
    assert main(["export", str(tmp_path), "--format", "urscript",
                 "--rate-full-scale", "1"]) == 2
    assert "--rate-full-scale" in capsys.readouterr().err


def test_preview_command_writes_html(job: Path, tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["preview", str(job)]) == 0
    assert (job / "preview.html").stat().st_size > 1_000_000
    assert main(["preview", str(tmp_path)]) == 2
    assert "mesp slice" in capsys.readouterr().err
