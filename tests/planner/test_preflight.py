"""Preflight: fit, units and critical surfaces of a model in seconds, and `mesp check`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from mesp_cell.cli import main
from planner.cell import CellConfig, load_cell
from planner.preflight import fits_gel, fits_tank, preflight
from slicer.config import load_job
from slicer.mesh_io import load_surface

W = 2.0  # mm, line width


def _box(path: Path, size: tuple[float, float, float]) -> Path:
    box = trimesh.creation.box(extents=size)
    box.apply_translation(np.array(size) / 2)
    box.export(path)
    return path


def test_fit_of_footprint_and_height(cell: CellConfig) -> None:
    inner = cell.tank.inner_size_mm[0] - 2 * cell.placement.wall_margin_mm
    assert fits_tank(cell, np.array([inner - 1.0, 50.0, 20.0])) == 0.0
    # a long bar fits only turned diagonally
    assert fits_tank(cell, np.array([1.2 * inner, 20.0, 20.0])) == 45.0
    assert fits_tank(cell, np.array([2.0 * inner, 20.0, 20.0])) is None
    assert fits_gel(cell, cell.tank.gel_fill_mm - cell.placement.offset_mm[2])
    assert not fits_gel(cell, cell.tank.gel_fill_mm)


def test_a_plausible_part_fits_and_names_its_critical_region(tmp_path: Path,
                                                            cell: CellConfig) -> None:
    surface = load_surface(_box(tmp_path / "b.stl", (40.0, 30.0, 20.0)))
    result = preflight(surface, load_job(), cell, W)
    assert result.ok, result.findings
    topics = [f.topic for f in result.findings]
    assert topics == ["size", "units", "tank", "gel", "reach", "walls", "critical"]
    critical = result.findings[-1].text
    assert critical.startswith("1 critical region (1200 mm^2): bottom:45@end 1200 mm^2")
    assert np.isclose(result.selection.regions[0].area, 1200.0)


def test_an_8_mm_part_suggests_other_units(tmp_path: Path, cell: CellConfig) -> None:
    surface = load_surface(_box(tmp_path / "b.stl", (8.0, 6.0, 4.0)))
    units = preflight(surface, load_job(), cell, W).findings[1]
    assert not units.ok and "--units cm makes it 80 mm" in units.text


def test_a_tall_part_fails_the_gel_and_names_no_wrong_cell(tmp_path: Path) -> None:
    cell = load_cell()
    tray = load_cell(Path(__file__).parents[2] / "planner" / "cells" / "tray.toml")
    surface = load_surface(_box(tmp_path / "b.stl", (40.0, 40.0, 120.0)))
    # in the tray (80 mm of gel) it does not fit; the default cell (240 mm) holds it
    result = preflight(surface, load_job(), tray, W, {"default": cell})
    found = {f.topic: f for f in result.findings}
    assert not found["gel"].ok and "it fits the bundled default cell" in found["gel"].text
    assert "reach" not in found  # not asked where the part does not fit


def test_mesp_check_answers_and_draws(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                      ) -> None:
    model = _box(tmp_path / "part.stl", (40.0, 30.0, 20.0))
    png = tmp_path / "part.png"
    assert main(["check", str(model), "--figure", str(png)]) == 0
    out = capsys.readouterr().out
    assert "reach: ok" in out and "critical: ok: 1 critical region" in out
    assert png.is_file() and png.stat().st_size > 10_000
    small = _box(tmp_path / "tiny.stl", (0.8, 0.6, 0.4))  # a part in cm read as mm
    assert main(["check", str(small), "--figure", str(png)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("mesp: error: 0.8 mm across")
    assert "--units m makes it 800 mm" not in err[0]  # 800 mm does not fit the tank
    assert "--units in makes it 20 mm" in err[0]


def _tube(path: Path, outer: float, wall: float, height: float) -> Path:
    ring = trimesh.creation.annulus(r_min=outer / 2 - wall, r_max=outer / 2, height=height,
                                    sections=64)
    ring.export(path)
    return path


def test_mesp_check_refuses_a_thin_tube_and_its_fix_works(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A 40 mm tube with 0.5 mm walls holds no line of the bundled profile; the size the
    check suggests, checked again, holds it."""
    model = _tube(tmp_path / "tube.stl", 30.0, 0.5, 40.0)
    png = tmp_path / "tube.png"
    assert main(["check", str(model), "--figure", str(png)]) == 1
    captured = capsys.readouterr()
    walls = next(line for line in captured.out.splitlines() if line.strip().startswith("walls"))
    assert "walls: PROBLEM" in walls and "slice it at --scale-to" in walls
    assert captured.err.startswith("mesp: error: ") and captured.err.count("\n") == 1
    size = walls.split("--scale-to ")[1].split()[0]
    assert main(["check", str(model), "--scale-to", size, "--figure", str(png)]) == 0
    assert "walls: ok" in capsys.readouterr().out


def _open_cup(path: Path, size: float) -> Path:
    """A cube of ``size`` mm with its top face missing (a hole no crack fill closes)."""
    box = trimesh.creation.box(extents=(size, size, size))
    box.apply_translation([size / 2] * 3)
    box.update_faces(box.face_normals[:, 2] < 0.5)
    box.export(path)
    return path


def _touching_cubes(path: Path, size: float) -> Path:
    """Two closed cubes sharing one vertical edge: closed, but non-manifold."""
    low = trimesh.creation.box(extents=(size, size, size))
    high = low.copy()
    high.apply_translation([size, size, 0.0])
    (low + high).export(path)
    return path


def test_mesp_check_names_the_mesh_problem_and_the_checked_repair(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = _open_cup(tmp_path / "cup.stl", 30.0)
    assert main(["check", str(model), "--figure", str(tmp_path / "cup.png")]) == 1
    captured = capsys.readouterr()
    mesh = captured.out.splitlines()[0]
    assert mesh.startswith("    mesh: PROBLEM: cup.stl is not watertight (4 open edges")
    assert "slice with --repair (checked: it filled 1 hole" in mesh
    assert "reach: ok" in captured.out  # the rest is checked on the repaired surface
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("mesp: error: cup.stl is not watertight")


def _cube_with_a_fin(path: Path, size: float) -> Path:
    """A closed cube with one triangle standing on a top edge: open, and the fill leaves it
    refused, so only fTetWild's wrap repairs it."""
    box = trimesh.creation.box(extents=(size, size, size))
    edge = np.flatnonzero(np.isclose(box.vertices[:, 2], size / 2)
                          & np.isclose(box.vertices[:, 0], size / 2))
    v = np.vstack([box.vertices, [[size / 2, 0.0, 1.5 * size]]])
    trimesh.Trimesh(v, np.vstack([box.faces, [[edge[0], edge[1], 8]]]),
                    process=False).export(path)
    return path


def test_mesp_check_offers_the_split_of_touching_cubes(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = _touching_cubes(tmp_path / "cubes.stl", 20.0)
    assert main(["check", str(model), "--figure", str(tmp_path / "cubes.png")]) == 1
    mesh = capsys.readouterr().out.splitlines()[0]
    assert "mesh: PROBLEM: cubes.stl is not watertight (1 non-manifold edges)" in mesh
    assert "slice with --repair (checked: it split the surface where its parts touch" in mesh


def test_mesp_check_says_when_the_repair_was_not_checked(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    from mesp_cell.commands import check
    from slicer import tet_cache

    monkeypatch.setenv(tet_cache.CACHE_ENV, str(tmp_path / "cache"))  # no stored wrap
    monkeypatch.setattr(check, "REPAIR_SECONDS", 0.0)
    model = _cube_with_a_fin(tmp_path / "fin.stl", 20.0)
    assert main(["check", str(model), "--figure", str(tmp_path / "fin.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "(2 open edges" in err[0]
    assert "or slice with --repair (fTetWild's wrap: not checked here" in err[0]
    assert "checked: it" not in err[0]
