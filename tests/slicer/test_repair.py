"""--repair: every hole of an open surface closed, and the one line saying what changed."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from core.errors import InputError
from mesp_cell.cli import main
from slicer.mesh_io import load_surface
from slicer.repair import fill_holes, load_repaired, repair_offer


def _open_cup(size: float = 30.0) -> trimesh.Trimesh:
    """A cube of ``size`` mm with its top face missing: a 4 x ``size`` mm hole."""
    box = trimesh.creation.box(extents=(size, size, size))
    box.apply_translation([size / 2] * 3)
    top = box.face_normals[:, 2] > 0.5
    box.update_faces(~top)
    box.remove_unreferenced_vertices()
    return box


def test_fill_closes_the_hole_and_measures_it() -> None:
    cup = _open_cup(30.0)
    v, f, fill = fill_holes(np.asarray(cup.vertices), np.asarray(cup.faces))
    closed = trimesh.Trimesh(v, f, process=False)
    assert closed.is_watertight and closed.is_winding_consistent
    assert fill.holes == 1 and fill.open_edges == 4
    assert fill.area_added == pytest.approx(900.0)  # the missing 30 x 30 mm face
    assert fill.largest_perimeter == pytest.approx(120.0)
    assert closed.volume == pytest.approx(27000.0)


def test_a_closed_surface_is_left_as_it_is() -> None:
    box = trimesh.creation.box(extents=(10.0, 10.0, 10.0))
    _, f, fill = fill_holes(np.asarray(box.vertices), np.asarray(box.faces))
    assert fill.holes == 0 and len(f) == len(box.faces)


def test_load_repaired_says_what_changed(tmp_path: Path) -> None:
    path = tmp_path / "cup.stl"
    _open_cup(30.0).export(path)
    with pytest.raises(InputError) as refused:
        load_surface(path)
    surface = load_repaired(path)
    assert surface.volume_mm3 == pytest.approx(27000.0)
    assert surface.notes[0] == ("--repair: filled 1 hole (4 open edges, largest 120.0 mm "
                                "round), added 900 mm^2 of surface")
    assert surface.source == path
    offer = repair_offer(path, "mm", refused.value)
    assert "re-run with --repair (checked: it filled 1 hole" in offer.one_line()


def test_units_scale_the_repair_line(tmp_path: Path) -> None:
    path = tmp_path / "cup.stl"
    _open_cup(3.0).export(path)  # 3 cm
    surface = load_repaired(path, "cm")
    assert "largest 120.0 mm round), added 900 mm^2" in surface.notes[0]


def test_slice_offers_and_applies_repair(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "cup.stl"
    _open_cup(20.0).export(path)
    out = tmp_path / "job"
    args = ["slice", str(path), "--out", str(out), "--until", "tetmesh", "--quiet",
            "--edge-length", "4"]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "re-run with --repair (checked" in err[0]
    assert main([*args, "--repair"]) == 0
    printed = capsys.readouterr().out
    assert "note: model: --repair: filled 1 hole (4 open edges" in printed
    assert (out / "tetmesh.npz").is_file()
