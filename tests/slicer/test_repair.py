"""--repair: every hole of an open surface closed or the surface wrapped, picked by the
refusal's reason, kept per input, and the one line saying what changed."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from core.errors import InputError
from mesp_cell.cli import main
from slicer import tet_cache, wrap_cache
from slicer.mesh_io import load_surface
from slicer.repair import fill_holes, load_repaired, repairable
from slicer.repair_offer import _refusal, offer_fix, repair_offer
from slicer.shell_split import non_manifold_edges
from slicer.surface_refusal import RepairRefused, SurfaceReason, SurfaceRefused
from slicer.winding_repair import Wrap, boundary_faces, wrap

# Seconds a test gives the check that --repair works (the host may be loaded; the 30 s the
# refusal waits is the product's limit, not what these tests measure).
WAIT = 600.0


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
    assert isinstance(refused.value, SurfaceRefused)
    assert refused.value.reason is SurfaceReason.OPEN
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


def _stacked_boxes(size: float = 20.0) -> trimesh.Trimesh:
    """Two closed cubes of ``size`` mm, one on the other: the face between them is there
    twice (once per cube), and every edge of it is used by 4 faces."""
    low = trimesh.creation.box(extents=(size, size, size))
    high = low.copy()
    high.apply_translation([0.0, 0.0, size])
    both = low + high
    both.merge_vertices()
    return both


def test_wrap_resolves_an_internal_face() -> None:
    boxes = _stacked_boxes(20.0)
    assert non_manifold_edges(np.asarray(boxes.faces)) > 0
    v, f, summary = wrap(np.asarray(boxes.vertices), np.asarray(boxes.faces))
    closed = trimesh.Trimesh(v, f, process=False)
    assert closed.is_watertight and closed.is_winding_consistent
    assert non_manifold_edges(f) == 0
    assert summary.volume_before == pytest.approx(16000.0)
    assert closed.volume == pytest.approx(16000.0, rel=0.03)
    assert summary.volume_after == pytest.approx(closed.volume)


def test_boundary_faces_of_one_tet_point_outwards() -> None:
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    f = boundary_faces(np.array([[0, 1, 2, 3]]))
    assert len(f) == 4
    assert trimesh.Trimesh(v, f, process=False).volume == pytest.approx(1 / 6)


def test_non_manifold_refusal_offers_and_applies_the_split(tmp_path: Path) -> None:
    path = tmp_path / "stacked.obj"
    _stacked_boxes(20.0).export(path)
    with pytest.raises(InputError) as refused:
        load_surface(path)
    assert "non-manifold edges" in refused.value.problem
    offer = repair_offer(path, "mm", refused.value, seconds=0.0)  # no fTetWild: at once
    assert "re-run with --repair (checked: it split the surface" in offer.one_line()
    surface = load_repaired(path)
    mesh = surface.as_trimesh()
    assert mesh.is_watertight and non_manifold_edges(surface.faces) == 0
    assert mesh.body_count == 1  # the two boxes joined into one 20 x 20 x 40 mm solid
    assert surface.volume_mm3 == pytest.approx(16000.0, rel=1e-9)
    assert np.allclose(surface.bbox_mm, (20.0, 20.0, 40.0))
    assert surface.notes[0] == (
        "--repair: split the surface where its parts touch (4 non-manifold edges, 4 touching "
        f"vertices) and joined its 2 shells into one solid with manifold3d (24 -> "
        f"{len(surface.faces)} faces, volume 16000 mm^3)")


def test_a_soup_is_still_refused(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    corners = rng.uniform(0.0, 30.0, size=(40, 1, 3)) + rng.uniform(0.0, 5.0, size=(40, 3, 3))
    soup = trimesh.Trimesh(corners.reshape(-1, 3), np.arange(120).reshape(-1, 3),
                           process=False)
    path = tmp_path / "soup.stl"
    soup.export(path)
    with pytest.raises(InputError) as refused:
        load_surface(path)
    assert "not watertight" in refused.value.problem
    offer = repair_offer(path, "mm", refused.value, seconds=WAIT)
    assert offer.fix.startswith(refused.value.fix)
    assert "(--repair was tried: filled 40 holes (the filled surface encloses no volume" in (
        offer.fix)
    with pytest.raises(InputError) as still:
        load_repaired(path)
    assert "its faces enclose nothing (open sheets, a polygon soup)" in still.value.fix


def test_a_wrap_past_its_time_is_not_offered_as_checked(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "fin.stl"
    _cube_with_a_fin(20.0).export(path)
    with pytest.raises(InputError) as refused:
        load_surface(path)
    monkeypatch.setenv(tet_cache.CACHE_ENV, str(tmp_path / "cache"))  # nothing stored
    offer = repair_offer(path, "mm", refused.value, seconds=0.0)
    assert offer.problem == refused.value.problem
    assert offer.fix.startswith(refused.value.fix)
    assert "or re-run with --repair (fTetWild's wrap: not checked here" in offer.fix
    assert "checked: it" not in offer.fix


def _cubes_sharing_an_edge(size: float = 10.0) -> trimesh.Trimesh:
    """Two closed cubes touching along one vertical edge (used by 4 faces)."""
    low = trimesh.creation.box(extents=(size, size, size))
    high = low.copy()
    high.apply_translation([size, size, 0.0])
    both = low + high
    both.merge_vertices()
    return both


def _cube_with_a_fin(size: float = 20.0) -> trimesh.Trimesh:
    """A closed cube with one triangle standing on a top edge: 2 open edges (a hole too
    large to be a crack) and 1 edge of 3 faces; filling the fin's loop leaves it refused."""
    box = trimesh.creation.box(extents=(size, size, size))
    edge = np.flatnonzero(np.isclose(box.vertices[:, 2], size / 2)
                          & np.isclose(box.vertices[:, 0], size / 2))
    v = np.vstack([box.vertices, [[size / 2, 0.0, 1.5 * size]]])
    return trimesh.Trimesh(v, np.vstack([box.faces, [[edge[0], edge[1], 8]]]), process=False)


def test_the_repair_is_picked_by_the_reason_not_the_words() -> None:
    words = "m.stl is not watertight (3 open edges)"
    assert repairable(SurfaceRefused("any words", "fix", SurfaceReason.OPEN))
    assert repairable(SurfaceRefused("any words", "fix", SurfaceReason.NON_MANIFOLD))
    assert not repairable(SurfaceRefused(words, "fix", SurfaceReason.FLAT))
    assert not repairable(InputError(words, "fix"))
    plain = InputError(words, "fix")
    assert repair_offer("m.stl", "mm", plain) is plain


def test_cubes_sharing_an_edge_are_split_into_two_shells(tmp_path: Path) -> None:
    path = tmp_path / "touching.stl"
    _cubes_sharing_an_edge(10.0).export(path)
    surface = load_repaired(path)
    mesh = surface.as_trimesh()
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.body_count == 2
    assert non_manifold_edges(surface.faces) == 0
    assert surface.volume_mm3 == pytest.approx(2000.0, rel=1e-4)
    assert "(1 non-manifold edges, 2 touching vertices)" in surface.notes[0]


def test_overlapping_boxes_sharing_an_edge_become_their_union(tmp_path: Path) -> None:
    """Box B turned 100 deg about box A's vertical corner edge, which is B's edge too (4
    faces): B reaches 10 deg into A. The repair is their union (manifold3d's own)."""
    a = trimesh.creation.box(extents=(10.0, 10.0, 10.0))
    a.apply_translation([-5.0, -5.0, 0.0])  # corner edge on the z axis, A at x, y < 0
    b = a.copy()
    b.apply_transform(trimesh.transformations.rotation_matrix(np.radians(280.0), [0, 0, 1]))
    both = a + b
    both.merge_vertices()
    assert non_manifold_edges(np.asarray(both.faces)) == 1
    path = tmp_path / "overlap.stl"
    both.export(path)
    with pytest.raises(SurfaceRefused) as refused:
        load_surface(path)
    assert refused.value.reason is SurfaceReason.NON_MANIFOLD
    surface = load_repaired(path)
    mesh = surface.as_trimesh()
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert non_manifold_edges(surface.faces) == 0
    overlap = trimesh.boolean.intersection([a, b], engine="manifold").volume
    assert overlap > 10.0  # a real overlap, counted once
    assert surface.volume_mm3 == pytest.approx(2000.0 - overlap, rel=1e-4)
    assert "joined its 2 shells into one solid" in surface.notes[0]


def test_an_open_surface_the_fill_cannot_close_is_wrapped(tmp_path: Path) -> None:
    path = tmp_path / "fin.stl"
    _cube_with_a_fin(20.0).export(path)
    with pytest.raises(SurfaceRefused) as refused:
        load_surface(path)
    assert refused.value.reason is SurfaceReason.OPEN
    surface = load_repaired(path)
    assert surface.as_trimesh().is_watertight
    assert surface.volume_mm3 == pytest.approx(8000.0, rel=0.03)  # the fin encloses nothing
    assert surface.notes[0].startswith("--repair: wrapped by fTetWild's winding-number test "
                                       "(2 open and 1 non-manifold edges resolved")


def _counting_wrap(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Count fTetWild's wraps made through the cache."""
    calls: list[int] = []
    real = wrap_cache.wrap_troubled

    def counted(vertices: np.ndarray, faces: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, Wrap]:
        calls.append(len(faces))
        return real(vertices, faces)

    monkeypatch.setattr(wrap_cache, "wrap_troubled", counted)
    return calls


def test_a_repeated_repair_reads_the_stored_wrap(tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(tet_cache.CACHE_ENV, str(tmp_path / "cache"))
    calls = _counting_wrap(monkeypatch)
    path = tmp_path / "fin.stl"
    _cube_with_a_fin(20.0).export(path)
    first = load_repaired(path)
    again = load_repaired(path, "cm")  # other units: the same wrap, scaled
    assert len(calls) == 1
    assert np.array_equal(10.0 * first.vertices, again.vertices)
    assert np.array_equal(first.faces, again.faces)
    assert list((tmp_path / "cache").glob("wrap-*.npz"))


def test_without_the_cache_every_repair_wraps_again(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(tet_cache.CACHE_ENV, "off")
    calls = _counting_wrap(monkeypatch)
    path = tmp_path / "fin.stl"
    _cube_with_a_fin(20.0).export(path)
    load_repaired(path)
    load_repaired(path)
    assert len(calls) == 2


def test_the_offer_checks_wrap_is_the_one_repair_uses(tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(tet_cache.CACHE_ENV, str(tmp_path / "cache"))
    path = tmp_path / "fin.stl"
    _cube_with_a_fin(20.0).export(path)
    with pytest.raises(InputError) as refused:
        load_surface(path)
    offer = repair_offer(path, "mm", refused.value, seconds=WAIT)  # wraps in a child
    assert isinstance(offer, SurfaceRefused) and offer.reason is SurfaceReason.OPEN
    calls = _counting_wrap(monkeypatch)
    surface = load_repaired(path)
    assert calls == []  # read back, not wrapped again
    assert f"(checked: it {surface.notes[0].removeprefix('--repair: ')})" in offer.fix


def test_the_offer_reads_what_repair_tried_from_its_type_not_its_words() -> None:
    refusal = SurfaceRefused("m.stl is not watertight (3 open edges)", "close it",
                             SurfaceReason.OPEN)
    tried = RepairRefused("cup after --repair v2.stl", "filled 1 hole (a b c)", "x")
    assert offer_fix(refusal, tried, 30.0) == (
        "close it (--repair was tried: filled 1 hole (a b c))")
    other = InputError("the --repair check ended without an answer", "slice with --repair")
    assert offer_fix(refusal, other, 30.0) == (
        "close it (--repair was tried: the --repair check ended without an answer)")


def test_a_refusal_sent_by_the_check_process_keeps_its_type() -> None:
    sent = RepairRefused("m.stl", "wrapped it: no inside", "fix")
    back = _refusal(sent.problem, sent.fix, sent.name, sent.tried)
    assert isinstance(back, RepairRefused) and back.tried == sent.tried
    assert back.one_line() == sent.one_line()
    plain = _refusal("m.stl: ended", "fix")
    assert type(plain) is InputError and plain.one_line() == "m.stl: ended; fix"


def test_a_wrap_and_the_bodies_kept_beside_it_are_joined(tmp_path: Path) -> None:
    """The finned cube (wrapped) and a closed cube pushed half into it (kept as it is): two
    overlapping shells, joined into one solid that counts the overlap once."""
    fin = _cube_with_a_fin(20.0)
    kept = trimesh.creation.box(extents=(10.0, 10.0, 10.0))
    kept.apply_translation([10.0, 0.0, 0.0])  # x 5..15: half inside the cube's x -10..10
    both = trimesh.Trimesh(np.vstack([fin.vertices, kept.vertices]),
                           np.vstack([fin.faces, kept.faces + len(fin.vertices)]), process=False)
    path = tmp_path / "fin_and_cube.stl"
    both.export(path)
    surface = load_repaired(path)
    mesh = surface.as_trimesh()
    assert mesh.is_watertight and mesh.body_count == 1
    assert surface.volume_mm3 == pytest.approx(8500.0, rel=0.03)
    assert "(1 of 2 bodies, the others kept as they are; " in surface.notes[0]
    assert "2 shells joined into one solid, " in surface.notes[0]
