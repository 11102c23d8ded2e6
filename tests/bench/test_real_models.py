"""Smoke test of the real-model benchmark: two small meshes nobody here made, end to end."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench.corpus import SHARED_MODELS, _shared_folder, generated_models, shared_models
from bench.real_models import _merge, _metrics, main, run_model, table


@pytest.mark.slow
@pytest.mark.skipif(not SHARED_MODELS.is_dir(), reason=f"{SHARED_MODELS} is not here")
def test_two_corpus_models_are_sliced_planned_and_inspected_or_refused_in_one_line(
        tmp_path: Path) -> None:
    models = {m.name: m for m in shared_models()}
    rows = [run_model(models[name], tmp_path, 30.0, 300.0, ["--layer-height", "0.8"],
                      voxel=0.5) for name in ("tube", "multibody")]
    for row in rows:
        sliced = row["slice"]
        assert sliced["status"] in ("ok", "exit 2"), sliced  # never a crash or a timeout
        if sliced["status"] != "ok":
            assert sliced["reason"], row  # a refusal says why
            continue
        metrics = row["metrics"]
        assert metrics["layers"] and 0.0 <= metrics["gap_contour"] <= 1.0
        assert metrics["height_max_mm"] < 3.0  # heights measured on the layers
        plan = row["plan"]
        assert plan["status"] in ("ok", "exit 2", "exit 3"), plan
        assert plan["status"] == "ok" or plan["reason"], plan
    assert table(rows).count("\n") == len(rows) + 1


@pytest.mark.slow
def test_the_generated_parts_are_closed_solids(tmp_path: Path) -> None:
    import trimesh

    for model in generated_models(tmp_path):
        mesh = trimesh.load(model.path)
        assert mesh.is_watertight and mesh.volume > 1000.0, model.name


def test_the_shared_folder_is_found_from_a_worktree_deeper_than_the_checkout(
        tmp_path: Path) -> None:
    (tmp_path / "shared" / "models").mkdir(parents=True)
    tree = tmp_path / "wt" / "name"
    tree.mkdir(parents=True)
    assert _shared_folder(tree) == tmp_path / "shared" / "models"


def test_rows_from_parallel_runs_are_merged_not_overwritten(tmp_path: Path) -> None:
    results = tmp_path / "results.json"
    _merge(results, {"model": "a", "slice": {"status": "ok"}})
    _merge(results, {"model": "b", "slice": {"status": "ok"}})  # another run, another model
    rows = _merge(results, {"model": "a", "plan": {"status": "ok"}})
    assert sorted(rows) == ["a", "b"] and "plan" in rows["a"] and "slice" in rows["b"]


def test_the_table_leaves_what_was_not_measured_blank_and_is_rebuilt_from_the_reports(
        tmp_path: Path) -> None:
    report = {"toolpath": {"coverage": {"contour": {"gap": 0.05, "overlap": 0.02},
                                        "stripe": {"gap": None, "overlap": None}},
                           "width_error": {"contour": {"p90": 0.04},
                                           "stripe": {"p90": float("nan")}},
                           "volume_error": float("nan")},
              "plan": {"status": "ok", "verified": {"ok": True, "alpha_deg": [71.0, 109.5],
                                                    "min_clearance_mm": 9.0}}}
    metrics = _metrics(report)
    assert (metrics["alpha_min"], metrics["alpha_max"]) == (71.0, 109.5)
    row = {"model": "m", "origin": "shared", "metrics": metrics,
           "slice": {"status": "ok", "reason": "", "s": 3.0}}
    line = table([row]).splitlines()[2]
    assert "nan" not in line and "| 5.0/2.0 | / | 4.0/ |" in line
    assert "71.0-109.5 | 9.0 |" in line
    # --table: the metrics again from the job's report, nothing run
    out = tmp_path / "out"
    (out / "m").mkdir(parents=True)
    (out / "m" / "report.json").write_text(json.dumps(report))
    _merge(out / "results.json", {**row, "metrics": {}})
    models = tmp_path / "models"
    models.mkdir()
    (models / "m.stl").write_text("solid m\nendsolid m\n")
    assert main(["--table", "--out", str(out), "--shared", str(models), "--models", "m"]) == 0
    assert "71.0-109.5" in (out / "table.md").read_text()
