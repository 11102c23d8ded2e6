"""Smoke test of the real-model benchmark: two small meshes nobody here made, end to end."""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.corpus import SHARED_MODELS, generated_models, shared_models
from bench.real_models import run_model, table

pytestmark = pytest.mark.slow


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


def test_the_generated_parts_are_closed_solids(tmp_path: Path) -> None:
    import trimesh

    for model in generated_models(tmp_path):
        mesh = trimesh.load(model.path)
        assert mesh.is_watertight and mesh.volume > 1000.0, model.name
