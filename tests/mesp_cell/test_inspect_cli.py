"""`mesp inspect`: report section, pictures, baselines and one-line errors."""

from __future__ import annotations

import itertools
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh

from core.report import read_report
from core.stages import TetMesh
from mesp_cell.cli import main
from sim import commercial
from sim.baseline import VOLUME_MATCHING_BETA, PlanarConfig, planar_toolpath
from sim.commercial import GCODE_FILE
from sim.deposition import EllipseMorphology


@pytest.fixture()
def job(tmp_path: Path) -> Path:
    box = trimesh.creation.box(extents=[5.0, 5.0, 3.0])
    box.apply_translation([2.5, 2.5, 1.5])
    morph = EllipseMorphology(beta=0.7)
    tp = planar_toolpath(box.vertices, box.faces, morph,
                         PlanarConfig(beta=0.7, width_mode="volume", perimeters=1))
    out = tmp_path / "job"
    out.mkdir()
    tp.save(out)
    box.export(out / "model.ply")
    return out


def test_inspect_writes_report_and_pictures(job: Path, capsys: pytest.CaptureFixture[str]
                                            ) -> None:
    assert main(["inspect", str(job), "--voxel", "0.25", "--quiet"]) == 0
    section = read_report(job)["inspect"]
    for key in ("infill_ratio", "pore_ratio", "over_deposition", "surface_error_mm",
                "per_layer", "voxel_mm", "volume_conservation_error"):
        assert key in section
    assert set(section["surface_error_mm"]) >= {"mean", "p95", "max"}
    assert 0.8 < section["infill_ratio"] <= 1.0
    assert abs(section["volume_conservation_error"]) < 0.02
    for name in section["figures"]:
        assert (job / name).stat().st_size > 1000
    out = capsys.readouterr().out
    assert "infill ratio %" in out and "multi-axis" in out


def test_inspect_with_planar_and_gcode_baselines(job: Path) -> None:
    assert main(["inspect", str(job), "--voxel", "0.5", "--baseline", "planar", "--quiet",
                 "--no-figures"]) == 0
    section = read_report(job)["inspect"]
    base = section["baseline"]
    assert base["kind"] == "planar" and "surface_error_mm" in base
    # Both line width rules are simulated and reported with their beta; the better is kept.
    modes = section["baselines"]
    assert set(modes) == {"overlap", "volume"}
    assert modes["overlap"]["beta"] == pytest.approx(np.sqrt(np.pi) / 2)
    assert modes["volume"]["width_mode"] == "volume"
    best = min(m["surface_error_mm"]["mean"] for m in modes.values())
    assert base["surface_error_mm"]["mean"] == best
    assert "flush" not in base  # the job has no tet mesh
    comparison = section["comparison"]
    assert comparison["surface_error_mean_mm"]["paper_planar"] == 0.49
    gcode = job / "part.gcode"
    lines = ["G21", "G90", "M82", "G92 E0"]
    e = 0.0
    for k, z in enumerate(np.arange(0.3, 3.0, 0.6)):
        lines.append(f"G0 X100 Y{100 + 0.5 * (k % 2)} Z{z:.2f}")
        for j in range(5):
            y = 100 + j + 0.5
            e += 5.0 * 0.6 * 1.0
            lines += [f"G0 X100 Y{y}", f"G1 X105 Y{y} E{e:.4f}"]
    gcode.write_text("\n".join(lines) + "\n")
    assert main(["inspect", str(job), "--voxel", "0.5", "--gcode", str(gcode), "--filament",
                 "0", "--quiet", "--no-figures"]) == 0
    base = read_report(job)["inspect"]["baseline"]
    assert base["kind"] == "gcode"
    assert base["commanded_volume_mm3"] == pytest.approx(75.0, rel=0.01)


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["inspect", "{missing}"], "does not exist"),
        (["inspect", "{empty}"], "toolpath.npz"),
        (["inspect", "{job}", "--voxel", "0"], "--voxel"),
        (["inspect", "{job}", "--voxel", "-1"], "--voxel"),
        (["inspect", "{job}", "--gcode", "{missing}"], "does not exist"),
        (["inspect", "{job}", "--flush"], "tetmesh.npz"),
        (["inspect", "{job}", "--as-planned"], "mesp plan"),
        (["inspect", "{job}", "--flow-tau", "-1"], "--flow-tau"),
        (["inspect", "{job}", "--flow-lead", "nan"], "--flow-lead"),
    ],
)
def test_user_mistakes_are_one_line(job: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                    args: list[str], needle: str) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    subs = {"missing": str(tmp_path / "nope"), "empty": str(empty), "job": str(job)}
    argv = [a.format(**subs) for a in args]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert err.startswith("mesp: error:") and needle in err
    assert "Traceback" not in err


def _box_tetmesh(size: tuple[float, float, float]) -> TetMesh:
    """The 6 Kuhn tets of the box [0, size], positively oriented."""
    corners = np.array([[(i >> a) & 1 for a in range(3)] for i in range(8)],
                       dtype=np.float64) * np.asarray(size)
    tets = []
    for a, b, _ in itertools.permutations(range(3)):
        t = [0, 1 << a, (1 << a) | (1 << b), 7]
        if np.linalg.det(corners[t[1:]] - corners[t[0]]) < 0:
            t[1], t[2] = t[2], t[1]
        tets.append(t)
    return TetMesh(vertices=corners, tets=np.asarray(tets, dtype=np.int32))


def test_flush_moves_exposed_waypoints_and_flushes_the_baseline(job: Path) -> None:
    _box_tetmesh((5.0, 5.0, 3.0)).save(job)
    assert main(["inspect", str(job), "--voxel", "0.5", "--flush", "--baseline", "planar",
                 "--baseline-width", "volume", "--quiet", "--no-figures"]) == 0
    section = read_report(job)["inspect"]
    # beta 0.7: h_f - H > 0, so the first and last layers stick out and are moved.
    assert section["flush"]["moved_up"] > 0 and section["flush"]["moved_down"] > 0
    assert section["baseline"]["flush"]["moved"] > 0
    assert set(section["baselines"]) == {"volume"}


def test_default_voxel_coarsens_for_large_models() -> None:
    from mesp_cell.console import ConsoleProgress
    from sim.voxel_choice import AUTO_VOXEL_BUDGET, DEFAULT_VOXEL_MM
    from sim.voxel_choice import auto_voxel as _auto_voxel

    quiet = ConsoleProgress(quiet=True)
    small = np.array([[0.0, 0.0, 0.0], [30.0, 30.0, 30.0]])
    assert _auto_voxel(small, quiet) == DEFAULT_VOXEL_MM
    big = np.array([[0.0, 0.0, 0.0], [200.0, 150.0, 120.0]])
    v = _auto_voxel(big, quiet)
    assert v > DEFAULT_VOXEL_MM
    assert np.prod((np.ptp(big, axis=0) + 8.0) / v) <= AUTO_VOXEL_BUDGET


def test_flush_is_not_applied_twice(job: Path) -> None:
    from core.report import update_report

    _box_tetmesh((5.0, 5.0, 3.0)).save(job)
    update_report(job, {"toolpath": {"flush": {"moved": 3}}})  # as mesp slice would record
    assert main(["inspect", str(job), "--voxel", "0.5", "--flush", "--quiet",
                 "--no-figures"]) == 0
    assert "flush" not in read_report(job)["inspect"]


needs_prusaslicer = pytest.mark.skipif(
    shutil.which(commercial.DEFAULT_EXECUTABLE) is None,
    reason="prusa-slicer is not installed (make baselines, or apt-get install prusa-slicer)")


@needs_prusaslicer
def test_inspect_cli_prusaslicer_baseline(job: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", str(job), "--voxel", "0.5", "--baseline", "prusaslicer",
                 "--quiet", "--no-figures"]) == 0
    section = read_report(job)["inspect"]
    base = section["baseline"]
    assert base["kind"] == "prusaslicer" and base["version"][0].isdigit()
    assert base["settings"]["layer_height_mm"] == pytest.approx(0.6, rel=0.05)
    assert base["settings"]["beta"] == pytest.approx(VOLUME_MATCHING_BETA)
    assert base["volume_conservation_error"] == pytest.approx(0.0, abs=0.02)
    assert 0.8 < base["infill_ratio"] <= 1.0
    assert "surface_error_mean_mm" in section["comparison"]
    assert (job / GCODE_FILE).is_file()
    assert "prusaslicer" in capsys.readouterr().out


def test_inspect_cli_without_prusaslicer_is_one_line(job: Path,
                                                     monkeypatch: pytest.MonkeyPatch,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(commercial, "DEFAULT_EXECUTABLE", "prusa-slicer-not-installed-xyz")
    assert main(["inspect", str(job), "--voxel", "0.5", "--baseline", "prusaslicer",
                 "--quiet", "--no-figures"]) == 2
    err = capsys.readouterr().err
    assert "not installed" in err and "make baselines" in err and "Traceback" not in err


def test_inspect_cli_names_the_model_when_model_ply_is_gone(
        job: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (job / "model.ply").unlink()
    (job / "report.json").write_text('{"job": {"model_file": "parts/box.stl"}}')
    assert main(["inspect", str(job), "--baseline", "prusaslicer", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "no model.ply" in err and "mesp slice parts/box.stl" in err


def _save_trajectory(job: Path, slow: float, n: int | None = None) -> None:
    """A trajectory passing each waypoint of DIR's toolpath (or of ``n`` waypoints) at the
    toolpath's speed, ``slow`` times slower on the segments of layer 1."""
    from core.stages import Toolpath
    from planner.trajectory import Trajectory

    tp = Toolpath.load(job)
    length = np.linalg.norm(np.diff(tp.position, axis=0), axis=1)
    dt = np.maximum(length, 0.01) / np.maximum(0.5 * (tp.speed[:-1] + tp.speed[1:]), 1e-9)
    dt = np.where(tp.layer[:-1] == 1, slow * dt, dt)
    t = np.concatenate([[0.0], np.cumsum(dt)])
    m = len(t) if n is None else n
    Trajectory(t=t[:m], q=np.zeros((m, 6)), qd=np.zeros((m, 6)), tcp=np.zeros((m, 3)),
               waypoint=np.arange(m, dtype=np.int32), alpha=np.full(m, 90.0),
               extrude=tp.extrude[:m].copy(), base_T=np.eye(4), tool_T=np.eye(4),
               model_T=np.eye(4)).save(job)


def test_inspect_as_planned_prints_at_the_trajectory_speeds(
        job: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _save_trajectory(job, slow=3.0)
    # an extruder that keeps its rate C (--constant-flow): layer 1's ink three times over
    assert main(["inspect", str(job), "--voxel", "0.25", "--as-planned", "--constant-flow",
                 "--quiet"]) == 0
    section = read_report(job)["inspect"]
    assert "inspect_as_planned.png" in section["figures"]
    assert (job / "inspect_as_planned.png").stat().st_size > 1000
    planned = section["as_planned"]
    assert planned["flow"] == "constant"
    assert 0.1 < planned["slowed_length_fraction"] < 0.9
    assert planned["speed_ratio_min"] == pytest.approx(1.0 / 3.0, rel=1e-6)
    assert planned["extra_ink_mm3"] > 0.2 * section["commanded_volume_mm3"]
    assert planned["over_deposition"] > section["over_deposition"]
    assert abs(planned["volume_conservation_error"]) < 0.02
    assert "as planned" in capsys.readouterr().out
    # the cell's synced extruder (the default) follows the slowdown: the ink per millimetre
    # stays the toolpath's but within about tau of the changes of speed
    assert main(["inspect", str(job), "--voxel", "0.25", "--as-planned", "--quiet",
                 "--no-figures"]) == 0
    section = read_report(job)["inspect"]
    synced = section["as_planned"]
    assert synced["flow"] == "synced" and synced["flow_tau_s"] == 0.2
    assert abs(synced["extra_ink_mm3"]) < 0.1 * planned["extra_ink_mm3"]
    assert synced["over_deposition"] < planned["over_deposition"]
    # at the toolpath's own speeds the prints are the same, whatever the extruder does
    _save_trajectory(job, slow=1.0)
    for flow in ([], ["--constant-flow"]):
        assert main(["inspect", str(job), "--voxel", "0.25", "--as-planned", "--quiet",
                     "--no-figures", *flow]) == 0
        section = read_report(job)["inspect"]
        assert section["as_planned"]["extra_ink_mm3"] == pytest.approx(0.0, abs=1e-6)
        assert section["as_planned"]["infill_ratio"] == pytest.approx(section["infill_ratio"])


def test_inspect_as_planned_refuses_another_jobs_trajectory(
        job: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _save_trajectory(job, slow=1.0, n=10)
    assert main(["inspect", str(job), "--as-planned", "--quiet", "--no-figures"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "planned for another toolpath" in err
    np.savez(job / "trajectory.npz", t=np.arange(3.0))  # not a trajectory
    assert main(["inspect", str(job), "--as-planned", "--quiet", "--no-figures"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.endswith(f"re-run mesp plan {job}")
