"""sim.pipeline: the virtual print as a library call, its section written and returned."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from core.report import read_report
from sim.baseline import PlanarConfig, planar_toolpath
from sim.baseline_prints import BaselineOptions
from sim.deposition import EllipseMorphology
from sim.pipeline import InspectOptions, inspect_job
from sim.voxel_choice import DEFAULT_VOXEL_MM, auto_voxel


@pytest.fixture()
def job(tmp_path: Path) -> Path:
    box = trimesh.creation.box(extents=[5.0, 5.0, 3.0])
    box.apply_translation([2.5, 2.5, 1.5])
    tp = planar_toolpath(box.vertices, box.faces, EllipseMorphology(beta=0.7),
                         PlanarConfig(beta=0.7, width_mode="volume", perimeters=1))
    out = tmp_path / "job"
    out.mkdir()
    tp.save(out)
    box.export(out / "model.ply")
    return out


def test_inspect_job_returns_the_section_it_writes(job: Path) -> None:
    result = inspect_job(job, InspectOptions(voxel_mm=0.5, figures=False))
    assert read_report(job)["inspect"] == result.section
    assert result.section["voxel_mm"] == 0.5 and "figures" not in result.section
    assert 0.8 < result.section["infill_ratio"] <= 1.0
    assert [label for label, _ in result.columns] == ["multi-axis"]


def test_a_planar_baseline_in_one_width_mode_is_its_column(job: Path) -> None:
    options = InspectOptions(voxel_mm=0.5, figures=False,
                             baseline=BaselineOptions(kind="planar", width="overlap"))
    result = inspect_job(job, options)
    assert set(result.section["baselines"]) == {"overlap"}
    assert [label for label, _ in result.columns] == ["multi-axis", "planar-overlap"]
    assert "surface_error_mean_mm" in result.section["comparison"]


class _Notes:
    def __init__(self) -> None:
        self.lines: list[str] = []

    def info(self, text: str) -> None:
        self.lines.append(text)


def test_a_coarsened_voxel_is_told() -> None:
    notes = _Notes()
    assert auto_voxel(np.array([[0.0, 0.0, 0.0], [10.0, 10.0, 10.0]]), notes) == DEFAULT_VOXEL_MM
    assert notes.lines == []
    v = auto_voxel(np.array([[0.0, 0.0, 0.0], [400.0, 400.0, 400.0]]), notes)
    assert v > DEFAULT_VOXEL_MM and f"--voxel {v:.2f}" in notes.lines[0]
