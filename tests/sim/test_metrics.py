"""Voxelisation and print-quality metrics on analytic deposits."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy import ndimage

from core.stages import Toolpath
from sim.deposition import Deposit
from sim.metrics import inspect_deposit, model_fraction
from sim.voxels import VoxelGrid, closing_cube, fill_enclosed, iso_points, voxelize_mesh


def _box(lo: tuple[float, float, float], hi: tuple[float, float, float]) -> trimesh.Trimesh:
    lo_a, hi_a = np.asarray(lo), np.asarray(hi)
    box = trimesh.creation.box(extents=hi_a - lo_a)
    box.apply_translation(0.5 * (lo_a + hi_a))
    return box


def _deposit_of(fill: np.ndarray, grid: VoxelGrid, layer: np.ndarray | None = None) -> Deposit:
    tags = layer if layer is not None else np.where(fill > 0, 0, -1).astype(np.int32)
    vol = float(fill.sum()) * grid.voxel_volume
    return Deposit(grid=grid, fill=fill.astype(np.float32), layer=tags, commanded_mm3=vol,
                   status="ok", trace=())


def test_voxelize_sphere_and_box_volumes() -> None:
    grid = VoxelGrid.around(np.full(3, -6.0), np.full(3, 6.0), 0.2)
    sphere = trimesh.creation.icosphere(4, 5.0)
    inside = voxelize_mesh(sphere.vertices, sphere.faces, grid)
    assert inside.sum() * grid.voxel_volume == pytest.approx(sphere.volume, rel=0.01)
    box = _box((-3.0, -2.0, -1.0), (3.0, 2.0, 1.0))
    frac = model_fraction(box, grid)
    assert frac.sum() * grid.voxel_volume == pytest.approx(48.0, rel=1e-3)
    # Open (non-watertight) input is not our business, but a box far off the grid is empty.
    far = _box((100.0, 100.0, 100.0), (101.0, 101.0, 101.0))
    assert not voxelize_mesh(far.vertices, far.faces, grid).any()


def test_model_fraction_is_exact_for_a_face_through_voxel_centres() -> None:
    grid = VoxelGrid(origin=(-1.125, -1.125, -1.125), voxel=0.25, shape=(30, 30, 30))
    box = _box((0.0, 0.0, 0.0), (5.0, 5.0, 5.0))  # faces pass through voxel centres
    frac = model_fraction(box, grid)
    # Exact on the faces; along the 12 edges the planar model overcounts by < 0.5 mm^3.
    assert frac.sum() * grid.voxel_volume == pytest.approx(125.0, rel=5e-3)


def test_iso_points_find_a_plane() -> None:
    grid = VoxelGrid(origin=(0.0, 0.0, 0.0), voxel=0.5, shape=(6, 6, 10))
    z = grid.axis_centers(2)
    field = np.clip(2.3 - z, 0.0, 1.0)[None, None, :].repeat(6, 0).repeat(6, 1)
    pts = iso_points(field, grid, 0.5)
    # Interior crossings only: the grid's own faces also bound the field (outside counts as 0).
    top = pts[(pts[:, 0] > 0.5) & (pts[:, 0] < 2.5) & (pts[:, 1] > 0.5) & (pts[:, 1] < 2.5)
              & (pts[:, 2] > 0.1)]
    assert len(top) == 16
    assert np.allclose(top[:, 2], 1.8, atol=1e-6)


def test_closing_bridges_narrow_gaps_only() -> None:
    mask = np.zeros((20, 20, 20), dtype=bool)
    mask[2:18, 2:18, 2:8] = True
    mask[2:18, 2:18, 9:15] = True  # a one-voxel slot between two slabs
    closed = closing_cube(mask, 1)
    assert closed[5:15, 5:15, 8].all()
    assert not closed[5:15, 5:15, 17].any()


def test_perfect_print_scores_perfectly() -> None:
    grid = VoxelGrid(origin=(-2.0, -2.0, -2.0), voxel=0.25, shape=(48, 48, 48))
    box = _box((0.0, 0.0, 0.0), (8.0, 8.0, 8.0))
    fill = model_fraction(box, grid)
    q = inspect_deposit(_deposit_of(fill, grid), box.vertices, box.faces)
    assert q.infill_ratio == pytest.approx(1.0, abs=1e-6)
    assert q.over_deposition == pytest.approx(0.0, abs=1e-6)
    assert q.pore_ratio == pytest.approx(0.0, abs=1e-6)
    s = q.surface.stats()
    assert s["max"] < 0.5 * grid.voxel
    assert np.all(np.abs(q.surface.map_distance) < grid.voxel)


def test_shifted_print_has_matching_over_and_under_deposition() -> None:
    grid = VoxelGrid(origin=(-2.0, -2.0, -2.0), voxel=0.25, shape=(48, 48, 48))
    box = _box((0.0, 0.0, 0.0), (8.0, 8.0, 8.0))
    shifted = _box((0.5, 0.0, 0.0), (8.5, 8.0, 8.0))
    q = inspect_deposit(_deposit_of(model_fraction(shifted, grid), grid), box.vertices,
                        box.faces)
    assert q.over_deposition == pytest.approx(0.5 / 8.0, rel=0.02)
    assert q.under_deposition == pytest.approx(0.5 / 8.0, rel=0.02)
    assert q.surface.stats()["max"] == pytest.approx(0.5, abs=0.1)
    far = q.surface.map_points[:, 0] > 7.9  # the +x face: ink sticks out by 0.5 mm
    assert np.median(q.surface.map_distance[far]) == pytest.approx(0.5, abs=0.1)
    near = q.surface.map_points[:, 0] < 0.1  # the -x face: the print falls 0.5 mm short
    assert np.median(q.surface.map_distance[near]) == pytest.approx(-0.5, abs=0.1)


def test_error_by_facing_finds_a_raised_top_and_a_short_bottom() -> None:
    grid = VoxelGrid(origin=(-2.0, -2.0, -2.0), voxel=0.25, shape=(48, 48, 52))
    box = _box((0.0, 0.0, 0.0), (8.0, 8.0, 8.0))
    lifted = _box((0.0, 0.0, 0.5), (8.0, 8.0, 8.5))  # the whole print sits 0.5 mm too high
    q = inspect_deposit(_deposit_of(model_fraction(lifted, grid), grid), box.vertices,
                        box.faces)
    facing = q.surface.by_facing()
    assert facing["up"]["signed_mean"] == pytest.approx(0.5, abs=0.05)
    assert facing["down"]["signed_mean"] == pytest.approx(-0.5, abs=0.05)
    assert abs(facing["side"]["signed_mean"]) < 0.05
    # a cube's six faces: a sixth up, a sixth down (edges go to the nearer face)
    assert facing["up"]["share"] == pytest.approx(1 / 6, abs=0.03)
    assert sum(f["share"] for f in facing.values()) == pytest.approx(1.0)
    # the contributions add up to the overall mean
    total = sum(f["contribution"] for f in facing.values())
    assert total == pytest.approx(q.surface.stats()["mean"], rel=1e-9)
    assert q.summary()["surface_error_by_facing"] == facing


def test_interior_infill_ignores_the_skin_but_not_a_core_pore() -> None:
    # an 8 mm box printed 0.5 mm short on the +x face: the infill ratio loses 1/16, the
    # interior (1 mm below the surface) is whole; a 2 mm pore in the core shows in both
    grid = VoxelGrid(origin=(-2.0, -2.0, -2.0), voxel=0.25, shape=(48, 48, 48))
    box = _box((0.0, 0.0, 0.0), (8.0, 8.0, 8.0))
    short = model_fraction(_box((0.0, 0.0, 0.0), (7.5, 8.0, 8.0)), grid)
    q = inspect_deposit(_deposit_of(short, grid), box.vertices, box.faces)
    assert q.infill_ratio == pytest.approx(1.0 - 0.5 / 8.0, rel=2e-3)
    assert q.interior_infill_ratio == pytest.approx(1.0, abs=1e-6)
    assert q.interior_depth_mm == 1.0
    hole = model_fraction(_box((3.0, 3.0, 3.0), (5.0, 5.0, 5.0)), grid)
    q = inspect_deposit(_deposit_of(np.clip(short - hole, 0.0, 1.0), grid), box.vertices,
                        box.faces)
    # the core is the 6 mm box 1 mm inside: 8 of its 216 mm^3 are the pore
    assert q.interior_infill_ratio == pytest.approx(1.0 - 8.0 / 216.0, rel=2e-3)
    thin = inspect_deposit(_deposit_of(short, grid), box.vertices, box.faces,
                           interior_depth_mm=5.0)
    assert np.isnan(thin.interior_infill_ratio)  # no voxel is 5 mm inside an 8 mm box


def test_enclosed_cavity_is_a_pore() -> None:
    grid = VoxelGrid(origin=(-2.0, -2.0, -2.0), voxel=0.25, shape=(48, 48, 48))
    box = _box((0.0, 0.0, 0.0), (8.0, 8.0, 8.0))
    fill = model_fraction(box, grid)
    hole = _box((3.0, 3.0, 3.0), (5.0, 5.0, 5.0))
    fill = np.clip(fill - model_fraction(hole, grid), 0.0, 1.0)
    q = inspect_deposit(_deposit_of(fill, grid), box.vertices, box.faces)
    assert q.pore_ratio == pytest.approx(8.0 / 512.0, rel=0.05)
    assert q.infill_ratio == pytest.approx(1.0 - 8.0 / 512.0, rel=1e-3)
    assert q.surface.stats()["max"] < grid.voxel  # a pore is not part of the outer surface


def test_cavity_of_the_design_is_not_a_pore() -> None:
    """A hollow box printed exactly: its sealed chamber is gel inside the printed body, but the
    model has no material there, so the pore ratio stays 0 (a 4 mm^3 gel pocket in its wall
    still counts)."""
    grid = VoxelGrid(origin=(-2.0, -2.0, -2.0), voxel=0.25, shape=(48, 48, 48))
    outer = _box((0.0, 0.0, 0.0), (8.0, 8.0, 8.0))
    chamber = _box((2.0, 2.0, 2.0), (6.0, 6.0, 6.0))
    chamber.invert()  # inward-facing: the model is the shell between the two boxes
    shell = trimesh.util.concatenate([outer, chamber])
    fill = model_fraction(shell, grid)
    q = inspect_deposit(_deposit_of(fill, grid), shell.vertices, shell.faces)
    assert q.pore_ratio == pytest.approx(0.0, abs=1e-6)
    assert q.infill_ratio == pytest.approx(1.0, abs=1e-6)
    pocket = model_fraction(_box((0.5, 3.0, 3.0), (1.5, 5.0, 5.0)), grid)
    q = inspect_deposit(_deposit_of(np.clip(fill - pocket, 0, 1), grid), shell.vertices,
                        shell.faces)
    assert q.pore_ratio == pytest.approx(4.0 / (512.0 - 64.0), rel=0.1)


def _hollow_box() -> trimesh.Trimesh:
    outer = _box((0.0, 0.0, 0.0), (8.0, 8.0, 8.0))
    chamber = _box((2.0, 2.0, 2.0), (6.0, 6.0, 6.0))
    chamber.invert()  # inward-facing: the model is the shell between the two boxes
    return trimesh.util.concatenate([outer, chamber])


def test_a_groove_on_a_designed_cavity_is_surface_error_not_a_pore() -> None:
    """A 0.5 mm deep groove in the chamber's ceiling opens into the chamber: like a groove on
    the outer surface it is the surface falling short, not gel trapped in the print; the same
    groove sealed off from the chamber by a 0.5 mm skin is a pore."""
    grid = VoxelGrid(origin=(-2.0, -2.0, -2.0), voxel=0.25, shape=(48, 48, 48))
    shell = _hollow_box()
    fill = model_fraction(shell, grid)
    groove = model_fraction(_box((3.0, 2.0, 6.0), (5.0, 6.0, 6.5)), grid)  # 4 mm^3
    q = inspect_deposit(_deposit_of(np.clip(fill - groove, 0, 1), grid), shell.vertices,
                        shell.faces)
    assert q.pore_ratio == pytest.approx(0.0, abs=1e-6)
    assert q.infill_ratio == pytest.approx(1.0 - 4.0 / 448.0, rel=1e-3)
    # the chamber's walls are measured: the groove's floor lies 0.5 mm from the model
    assert q.surface.stats()["max"] == pytest.approx(0.5, abs=0.1)
    ceiling = (np.abs(q.surface.map_points[:, 2] - 6.0) < 0.01) & (
        np.abs(q.surface.map_points[:, 0] - 4.0) < 0.8)
    assert ceiling.any()
    assert np.median(q.surface.map_distance[ceiling]) == pytest.approx(-0.5, abs=0.1)
    sealed = model_fraction(_box((3.0, 2.5, 6.5), (5.0, 5.5, 7.0)), grid)  # 3 mm^3
    q = inspect_deposit(_deposit_of(np.clip(fill - sealed, 0, 1), grid), shell.vertices,
                        shell.faces)
    assert q.pore_ratio == pytest.approx(3.0 / 448.0, rel=0.1)


def test_fill_enclosed_matches_scipy_and_keeps_seeded_cavities_open() -> None:
    rng = np.random.default_rng(3)
    mask = ndimage.binary_dilation(rng.random((30, 24, 20)) < 0.03) | (
        rng.random((30, 24, 20)) < 0.35)
    assert np.array_equal(fill_enclosed(mask), ndimage.binary_fill_holes(mask))
    shell = np.ones((9, 9, 9), dtype=bool)
    shell[2:7, 2:7, 2:7] = False
    shell[4, 4, 4] = True
    assert fill_enclosed(shell).all()
    seeds = np.zeros_like(shell)
    seeds[3, 3, 3] = True
    kept = fill_enclosed(shell, seeds)
    assert np.array_equal(kept, shell)


def test_per_layer_attribution_adds_up() -> None:
    grid = VoxelGrid(origin=(-2.0, -2.0, -2.0), voxel=0.25, shape=(48, 48, 48))
    box = _box((0.0, 0.0, 0.0), (8.0, 8.0, 8.0))
    fill = model_fraction(_box((0.0, 0.0, 0.0), (8.0, 8.0, 9.0)), grid)  # 1 mm too tall
    z = grid.axis_centers(2)
    tags = np.where(fill > 0, np.clip((z // 1.0).astype(np.int32), 0, 8)[None, None, :], -1)
    n = 9
    pos = np.stack([np.full(n, 4.0), np.full(n, 4.0), np.arange(n) + 0.5], axis=1)
    tp = Toolpath(position=pos, normal=np.tile([0.0, 0.0, 1.0], (n, 1)),
                  layer=np.arange(n), path=np.zeros(n, dtype=np.int32),
                  height=np.ones(n), width=np.ones(n), speed=np.ones(n),
                  extrude=np.ones(n, dtype=bool), pattern=np.ones(n, dtype=np.int8))
    q = inspect_deposit(_deposit_of(fill, grid, tags.astype(np.int32)), box.vertices,
                        box.faces, tp)
    assert q.layers is not None
    assert q.layers.model_mm3.sum() == pytest.approx(q.model_mm3, rel=1e-6)
    assert q.layers.over_mm3.sum() == pytest.approx(q.over_deposition * q.model_mm3, rel=1e-6)
    assert q.layers.over_mm3[q.layers.layer == 8][0] == pytest.approx(64.0, rel=0.02)
    assert q.layers.over_mm3[q.layers.layer < 8].sum() == pytest.approx(0.0, abs=1e-6)
    summary = q.summary()
    assert set(summary) >= {"infill_ratio", "interior_infill_ratio", "pore_ratio",
                            "over_deposition",
                            "surface_error_mm", "per_layer"}


def test_signed_distance_signs_by_pseudonormal_on_closed_meshes_only() -> None:
    import igl

    from sim.metrics import _signed_distance

    ball = trimesh.creation.icosphere(subdivisions=3, radius=10.0)
    pts = np.random.default_rng(0).uniform(-14.0, 14.0, (2000, 3))
    winding = igl.signed_distance(pts, ball.vertices, ball.faces.astype(np.int64),
                                  sign_type=igl.SIGNED_DISTANCE_TYPE_WINDING_NUMBER)[0]
    assert np.allclose(_signed_distance(pts, ball), winding)  # pseudonormal, same result
    r = np.linalg.norm(pts, axis=1)
    clear = np.abs(r - 10.0) > 0.5  # away from the facets' chordal error
    assert np.array_equal(np.sign(_signed_distance(pts, ball))[clear], np.sign(r - 10.0)[clear])
    cap = trimesh.Trimesh(ball.vertices, ball.faces[:-10])  # open: the winding number decides
    assert not cap.is_watertight
    d = _signed_distance(pts, cap)
    assert np.isfinite(d).all()
