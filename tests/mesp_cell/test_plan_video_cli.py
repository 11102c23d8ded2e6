"""`mesp plan DIR --video`: the dry-run video and contact sheet next to the plan figures."""

from __future__ import annotations

from pathlib import Path

import pytest

from core.report import read_report
from mesp_cell.cli import main
from tests.planner import synthetic


def test_plan_video_writes_mp4_and_sheet(tmp_path: Path) -> None:
    synthetic.lines(n_lines=2, length=10.0).save(tmp_path)
    assert main(["plan", str(tmp_path), "--video", "--speedup", "8", "--video-size", "160x120",
                 "--render", "--quiet"]) == 0
    video = read_report(tmp_path)["plan"]["video"]
    if "skipped" in video:
        pytest.skip(video["skipped"])
    assert (tmp_path / video["path"]).stat().st_size > 1000
    assert (tmp_path / video["sheet"]).is_file()
    assert video["size_px"] == [160, 128] and video["frames"] >= 2
    assert (tmp_path / "figures" / "plan_twin.png").is_file()


def test_bad_video_size_is_a_one_line_error(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    synthetic.lines(n_lines=1, length=5.0).save(tmp_path)
    assert main(["plan", str(tmp_path), "--video", "--video-size", "big", "--quiet"]) == 2
    assert "WIDTHxHEIGHT" in capsys.readouterr().err
