"""`mesp slice` end to end: stage files, report keys, and one-line errors for bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from core.stages import Field, Layers, TetMesh, Toolpath

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"


def mesp(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    """Run the `mesp` console as a user would, in a child process."""
    return subprocess.run(
        [sys.executable, "-m", "mesp_cell.cli", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=600,
        check=False,
    )


@pytest.fixture(scope="module")
def cube_job(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("cube")
    proc = mesp(
        "slice",
        str(EXAMPLES / "cube.stl"),
        "--job",
        str(EXAMPLES / "cube.toml"),
        "--edge-length",
        "4",
        "--out",
        str(out),
        cwd=out,
    )
    assert proc.returncode == 0, proc.stderr
    return out


def test_slice_writes_every_stage_and_design_report_keys(cube_job: Path) -> None:
    mesh = TetMesh.load(cube_job)
    field = Field.load(cube_job)
    layers = Layers.load(cube_job)
    toolpath = Toolpath.load(cube_job)
    assert len(field.g) == len(mesh.vertices)
    assert layers.layer_count == len(field.iso)
    assert set(np.unique(toolpath.layer)) <= set(range(layers.layer_count))
    report = json.loads((cube_job / "report.json").read_text())
    for section, keys in {
        "model": ["volume_mm3", "bbox_mm"],
        "mesh": ["tets", "vertices"],
        "slicing": ["layers", "iterations", "height_mm", "height_std_initial_mm"],
        "toolpath": [
            "waypoints",
            "paths",
            "length_mm",
            "deposited_volume_mm3",
            "volume_error",
            "width_error",
            "width_error_undeformed",
            "bend_relief",
            "width_error_poisson_stripe",
        ],
        "timing_s": ["load", "tetrahedralize", "slicing", "toolpath", "total"],
    }.items():
        for key in keys:
            assert key in report[section], f"{section}.{key}"
    for stat in ("mean", "std", "min", "max", "p5", "p95"):
        assert stat in report["slicing"]["height_mm"]
    assert report["model"]["volume_mm3"] == pytest.approx(8000.0, rel=1e-6)
    assert abs(report["toolpath"]["volume_error"]) < 0.02
    assert report["toolpath"]["waypoints"] == len(toolpath)
    # the job records the profile it was sliced with (a fresh home: the factory profile)
    from slicer.extrusion import load_job_profile

    recorded = load_job_profile(cube_job)
    assert report["toolpath"]["profile"]["sha256"] == recorded.sha256
    assert report["toolpath"]["bend_relief"]["limit_deg"] == 20.0  # the bundled cell's range
    # the planner's bend test, run at slicing time on the toolpath: nothing it would refuse
    assert report["printability"]["refused_waypoints"] == 0
    assert report["printability"]["alpha_range_deg"] == [70.0, 110.0]


def test_slice_writes_exports_and_pictures(cube_job: Path) -> None:
    layers = Layers.load(cube_job)
    plys = sorted((cube_job / "layers_ply").glob("layer_*.ply"))
    assert len(plys) == layers.layer_count
    first = trimesh.load(plys[0], process=False)
    assert len(first.faces) == len(layers.layer(0).faces)
    assert sorted((cube_job / "layers_txt").glob("*.txt"))
    for name in ("layer_height_histogram.png", "convergence.png", "section.png"):
        assert (cube_job / "figures" / name).stat().st_size > 1000
    assert (cube_job / "model.ply").is_file() and (cube_job / "job.toml").is_file()
    # fTetWild's debug files must not land in the user's working directory.
    assert not list(cube_job.glob("__*"))


def test_planar_cube_layers_are_flat_at_target_height(cube_job: Path) -> None:
    layers = Layers.load(cube_job)
    for k in range(layers.layer_count):
        z = layers.layer(k).vertices[:, 2]
        assert np.ptp(z) < 1e-6
    np.testing.assert_allclose(layers.vertex_height, 20.0 / layers.layer_count, rtol=1e-6)


def _write(path: Path, data: bytes | str) -> Path:
    path.write_bytes(data.encode() if isinstance(data, str) else data)
    return path


def _open_box(path: Path) -> Path:
    box = trimesh.creation.box((10, 10, 10))
    box.update_faces(np.arange(len(box.faces)) > 1)  # remove one side: a big hole
    box.export(path)
    return path


def _inverted_flat(path: Path) -> Path:
    flat = trimesh.Trimesh([[0, 0, 0], [10, 0, 0], [0, 10, 0]], [[0, 1, 2], [0, 2, 1]])
    flat.export(path)
    return path


BAD_INPUTS = {
    "missing": (lambda d: d / "nope.stl", "does not exist"),
    "text as stl": (lambda d: _write(d / "t.stl", "hello, not a mesh\n"), "stl"),
    "empty": (lambda d: _write(d / "e.stl", b""), "empty"),
    "open box": (lambda d: _open_box(d / "open.stl"), "open"),
    "flat": (lambda d: _inverted_flat(d / "flat.stl"), "volume"),
    "wrong suffix": (lambda d: _write(d / "model.step", "ISO-10303-21;"), "step"),
}


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_bad_model_is_one_line_error(tmp_path: Path, case: str) -> None:
    make, words = BAD_INPUTS[case]
    model = make(tmp_path)
    proc = mesp("slice", str(model), "--out", str(tmp_path / "out"))
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    errors = [line for line in lines if line.startswith("mesp: error:")]
    assert errors == lines[-1:], proc.stderr  # one error line, the last one
    assert words.lower() in errors[0].lower()
    assert "Traceback" not in proc.stderr
    assert "done in" not in proc.stderr  # the failed stage is not reported as done


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--layer-height", "-1"], "layer_height_mm"),
        (["--critical", "sideways"], "not understood"),
        (["--units", "m"], "larger than"),
        (["--edge-length", "0.001"], "edge_length_mm"),
    ],
)
def test_bad_option_is_one_line_error(tmp_path: Path, args: list[str], words: str) -> None:
    proc = mesp("slice", str(EXAMPLES / "cube.stl"), "--out", str(tmp_path / "o"), *args)
    assert proc.returncode == 2, proc.stderr
    errors = [line for line in proc.stderr.splitlines() if line.startswith("mesp: error:")]
    assert len(errors) == 1 and words in errors[0], proc.stderr
    assert "Traceback" not in proc.stderr


def test_bad_job_file_is_one_line_error(tmp_path: Path) -> None:
    job = _write(tmp_path / "job.toml", "[slicing]\nlayer_hieght_mm = 0.5\n")
    proc = mesp("slice", str(EXAMPLES / "cube.stl"), "--job", str(job), "--out", str(tmp_path))
    assert proc.returncode == 2
    assert "unknown key 'job.slicing.layer_hieght_mm'" in proc.stderr


def test_help_explains_the_command() -> None:
    proc = mesp("slice", "--help")
    assert proc.returncode == 0
    for word in ("--layer-height", "--edge-length", "--critical", "--planar", "toolpath.npz"):
        assert word in proc.stdout


def test_slicer_notes_reach_the_operator(tmp_path: Path) -> None:
    """A critical selector whose position condition keeps nothing is not an error (the
    job still slices), but the operator is told, even with --quiet."""
    proc = mesp("slice", str(EXAMPLES / "cube.stl"), "--job", str(EXAMPLES / "cube.toml"),
                "--edge-length", "4", "--critical", "bottom", "--critical", "top@z>100",
                "--until", "layers", "--quiet", "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "note: slicing: critical selector 'top@z>100' kept no patch" in proc.stdout
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert "critical selector 'top@z>100' kept no patch" in report["slicing"]["notes"]


def test_no_baselines_flag_turns_the_baseline_measurements_off() -> None:
    import argparse

    from mesp_cell.commands import slice as slice_command

    parser = argparse.ArgumentParser()
    slice_command.register(parser.add_subparsers())
    on = parser.parse_args(["slice", "m.stl", "--out", "o"])
    off = parser.parse_args(["slice", "m.stl", "--out", "o", "--no-baselines"])
    assert slice_command.job_from_args(on).toolpath.measure_baselines
    assert not slice_command.job_from_args(off).toolpath.measure_baselines


def test_slice_passes_the_chosen_cells_path_accelerations(tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """`mesp slice --cell CELL` shapes the stripe joins' speed ramps to that cell's arm
    ([planning] path_accel_mm_s2, path_turn_accel_rad_s2), not the bundled cell's."""
    import argparse

    from core.path_accel import PathAccel
    from mesp_cell.commands import slice as slice_command
    from slicer import pipeline

    cell = tmp_path / "slow_arm.toml"
    cell.write_text("[planning]\npath_accel_mm_s2 = 35.0\npath_turn_accel_rad_s2 = 0.75\n")
    seen: dict[str, object] = {}

    class Sliced(Exception):
        pass

    def spy(*args: object, **kw: object) -> None:
        seen.update(kw)
        raise Sliced

    monkeypatch.setattr(pipeline, "slice_model", spy)
    parser = argparse.ArgumentParser()
    slice_command.register(parser.add_subparsers())
    for given, expected in ((["--cell", str(cell)], PathAccel(35.0, 0.75)),
                            ([], PathAccel.bundled())):
        args = parser.parse_args(["slice", str(EXAMPLES / "cube.stl"), "--out",
                                  str(tmp_path / "out"), "--quiet", *given])
        with pytest.raises(Sliced):
            slice_command.run(args)
        assert seen["accel"] == expected
