"""bench/identical_outputs.py: equal job directories pass, any changed value is named."""

from __future__ import annotations

import json
import shutil
import uuid
from pathlib import Path

import numpy as np

from bench.identical_outputs import differences, main


def _job(root: Path) -> Path:
    root.mkdir()
    np.savez(root / "toolpath.npz", position=np.arange(6.0).reshape(2, 3),
             speed=np.array([1.0, np.nan]))
    (root / "report.json").write_text(json.dumps(
        {"plan": {"duration_s": 3.5, "timing_s": {"velocity": 0.1}},
         "job": {"out": str(root.resolve())}}))
    (root / "figure.png").write_bytes(b"png")
    (root / "preview.html").write_text(f'<div id="{uuid.uuid4()}">plot</div>')
    return root


def test_the_same_outputs_are_identical_whatever_the_times_paths_and_uuids(tmp_path: Path) -> None:
    a = _job(tmp_path / "a")
    b = _job(tmp_path / "b")
    report = json.loads((b / "report.json").read_text())
    report["plan"]["timing_s"]["velocity"] = 9.0  # wall-clock time: ignored
    (b / "report.json").write_text(json.dumps(report))
    assert differences(a, b) == []
    assert main([str(a), str(b)]) == 0


def test_a_changed_array_value_or_file_is_reported(tmp_path: Path) -> None:
    a = _job(tmp_path / "a")
    b = tmp_path / "b"
    shutil.copytree(a, b)
    moved = np.arange(6.0).reshape(2, 3) + np.array([0.0, 0.0, 1e-12])
    np.savez(b / "toolpath.npz", position=moved, speed=np.array([1.0, np.nan]))
    report = json.loads((b / "report.json").read_text())
    report["plan"]["duration_s"] = 3.6
    (b / "report.json").write_text(json.dumps(report))
    (b / "figure.png").write_bytes(b"png2")
    found = differences(a, b)
    assert any(d.startswith("toolpath.npz:position: 2 of 6") for d in found)
    assert any("plan.duration_s" in d for d in found)
    assert "figure.png: bytes differ" in found
    assert differences(a, b, skip_figures=True) == [d for d in found if "figure" not in d]
    assert main([str(a), str(b)]) == 1
