"""Deposition model: volume, filament shape, infill of a staggered raster, pores at a gap."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from core.errors import InputError
from core.stages import Toolpath
from sim.deposition import (
    DepositionConfig,
    EllipseMorphology,
    covering_grid,
    deposit,
    extrusion_segments,
)
from sim.metrics import inspect_deposit
from sim.voxels import VoxelGrid


def _toolpath(points: list[np.ndarray], layers: list[int], speed: float, height: float,
              width: float, normal: tuple[float, float, float] = (0.0, 0.0, 1.0),
              extrude: list[np.ndarray] | None = None) -> Toolpath:
    counts = [len(p) for p in points]
    n = sum(counts)
    return Toolpath(
        position=np.concatenate(points),
        normal=np.tile(normal, (n, 1)),
        layer=np.repeat(layers, counts),
        path=np.repeat(np.arange(len(points)), counts),
        height=np.full(n, height),
        width=np.full(n, width),
        speed=np.full(n, speed),
        extrude=np.concatenate(extrude) if extrude is not None else np.ones(n, dtype=bool),
        pattern=np.ones(n, dtype=np.int8),
    )


def _line(a: np.ndarray, b: np.ndarray, step: float = 0.4) -> np.ndarray:
    n = max(int(np.ceil(np.linalg.norm(b - a) / step)), 1) + 1
    return a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)


def raster_cube(side: float, morph: EllipseMorphology, stagger: bool = True,
                skip: tuple[int, range, float, float] | None = None) -> Toolpath:
    """Volume-matched raster of the cube [0, side]^3: H from beta, W = C / (H v).

    The first and last layers sit half a filament height inside the bottom and top faces, so
    no filament sticks out of the cube; the volume is still side^3.
    ``skip`` = (layer, lines, s0, s1): those lines do not extrude between s0 and s1 (mm).
    """
    n_layers = round(side / 0.6)
    h = side / n_layers
    v0 = morph.speed_for_height(h / morph.beta)
    n_lines = max(1, round(side / (morph.rate_mm3_s / (h * v0))))
    w = side / n_lines
    v = morph.rate_mm3_s / (h * w)  # exact volume match for the rounded line count
    h_f = float(morph.filament_size(np.array([v]))[1][0])
    pts, layers, ext = [], [], []
    for k in range(n_layers):
        z = 0.5 * h_f + k * (side - h_f) / (n_layers - 1)
        for j in range(n_lines):
            c = (j + 0.5) * w
            a, b = (0.0, side) if j % 2 == 0 else (side, 0.0)
            if k % 2 == 1 and stagger:
                p = _line(np.array([c, a, z]), np.array([c, b, z]))
                s = p[:, 1]
            else:
                p = _line(np.array([a, c, z]), np.array([b, c, z]))
                s = p[:, 0]
            on = np.ones(len(p), dtype=bool)
            if skip is not None and skip[0] == k and j in skip[1]:
                on = ~((s > skip[2]) & (s < skip[3]))
            pts.append(p)
            layers.append(k)
            ext.append(on)
    return _toolpath(pts, layers, v, h, w, extrude=ext)


def _cube_mesh(side: float) -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=[side, side, side])
    box.apply_translation([0.5 * side] * 3)
    return box


def test_straight_filament_deposits_area_times_length() -> None:
    morph = EllipseMorphology(rate_mm3_s=6.57, aspect=0.75)
    speed, length = 4.0, 12.0
    tp = _toolpath([_line(np.zeros(3), np.array([length, 0.0, 0.0]))], [0], speed, 0.6, 1.5)
    dep = deposit(tp, morph, DepositionConfig(voxel_mm=0.1))
    area = morph.rate_mm3_s / speed
    assert dep.commanded_mm3 == pytest.approx(area * length, rel=1e-9)
    assert dep.deposited_mm3 == pytest.approx(area * length, rel=0.02)
    assert dep.status == "ok"
    # The filament's cross-section: ellipse w_f across (y) and h_f up (z), centred on the tip.
    w_f, h_f = (float(x[0]) for x in morph.filament_size(np.array([speed])))
    solid = dep.fill >= 0.5
    g = dep.grid
    y, z = g.axis_centers(1), g.axis_centers(2)
    mid = int(np.argmin(np.abs(g.axis_centers(0) - 0.5 * length)))
    ys = y[solid[mid].any(axis=1)]
    zs = z[solid[mid].any(axis=0)]
    assert ys.max() - ys.min() + g.voxel == pytest.approx(w_f, abs=2 * g.voxel)
    assert zs.max() - zs.min() + g.voxel == pytest.approx(h_f, abs=2 * g.voxel)
    assert abs(0.5 * (zs.max() + zs.min())) < g.voxel
    # Flat ends: nothing beyond the segment's ends along x (within a voxel).
    xs = g.axis_centers(0)[solid.any(axis=(1, 2))]
    assert xs.min() > -g.voxel and xs.max() < length + g.voxel


def test_cross_section_follows_the_nozzle_axis() -> None:
    morph = EllipseMorphology(aspect=0.5)  # h_f = w_f / 2: orientation is visible
    tp = _toolpath([_line(np.zeros(3), np.array([8.0, 0.0, 0.0]))], [0], 3.0, 0.6, 1.5,
                   normal=(0.0, 1.0, 0.0))
    dep = deposit(tp, morph, DepositionConfig(voxel_mm=0.1))
    w_f, h_f = (float(x[0]) for x in morph.filament_size(np.array([3.0])))
    solid = dep.fill >= 0.5
    span_y = solid.any(axis=(0, 2)).sum() * dep.grid.voxel
    span_z = solid.any(axis=(0, 1)).sum() * dep.grid.voxel
    assert span_y == pytest.approx(h_f, abs=0.25)  # height along the normal (+y)
    assert span_z == pytest.approx(w_f, abs=0.25)  # width across the motion


def test_overlapping_ink_is_displaced_and_volume_is_conserved() -> None:
    morph = EllipseMorphology()
    line = _line(np.zeros(3), np.array([10.0, 0.0, 0.0]))
    tp = _toolpath([line, line[::-1], line], [0, 1, 2], 5.0, 0.6, 1.5)  # same place 3x
    dep = deposit(tp, morph)
    assert dep.deposited_mm3 == pytest.approx(dep.commanded_mm3, rel=1e-5)
    assert dep.fill.max() <= 1.0 + 1e-4
    assert dep.status == "ok"
    assert sum(t.displaced_mm3 for t in dep.trace[1:]) > 0.5 * dep.commanded_mm3 / 3
    assert set(np.unique(dep.layer)) == {-1, 0, 1, 2}


def test_travel_moves_and_other_paths_do_not_deposit() -> None:
    morph = EllipseMorphology()
    a = _line(np.zeros(3), np.array([5.0, 0.0, 0.0]))
    b = _line(np.array([0.0, 5.0, 0.0]), np.array([5.0, 5.0, 0.0]))
    off = [np.ones(len(a), dtype=bool), np.zeros(len(b), dtype=bool)]
    seg = extrusion_segments(_toolpath([a, b], [0, 0], 5.0, 0.6, 1.5, extrude=off), morph)
    assert np.allclose(seg.length.sum(), 5.0)
    assert np.all(seg.start[:, 1] == 0.0)


def test_staggered_raster_cube_is_solid() -> None:
    side = 10.0
    # The overlap at which filament and path cross-sections match (pi/4 w_f h_f = W H).
    morph = EllipseMorphology(beta=float(np.sqrt(np.pi) / 2))
    tp = raster_cube(side, morph)
    mesh = _cube_mesh(side)
    grid = covering_grid(tp, morph, mesh.bounds)
    dep = deposit(tp, morph, grid=grid)
    assert dep.deposited_mm3 == pytest.approx(side**3, rel=0.02)  # volume matched by design
    q = inspect_deposit(dep, mesh.vertices, mesh.faces, tp)
    assert q.infill_ratio >= 0.99
    assert q.pore_ratio < 0.01
    assert q.over_deposition < 0.01


def test_staggering_beats_stacking_at_large_overlap() -> None:
    # Paper figure 3(c, d): same volume, same layers; only the raster direction alternates.
    side = 8.0
    morph = EllipseMorphology(beta=0.5)
    mesh = _cube_mesh(side)
    infill = {}
    for stagger in (True, False):
        tp = raster_cube(side, morph, stagger=stagger)
        dep = deposit(tp, morph, grid=covering_grid(tp, morph, mesh.bounds))
        infill[stagger] = inspect_deposit(dep, mesh.vertices, mesh.faces).infill_ratio
    assert infill[True] > infill[False] + 0.01


def test_gap_in_the_toolpath_leaves_pores_there() -> None:
    side = 8.0
    morph = EllipseMorphology(beta=float(np.sqrt(np.pi) / 2))
    mesh = _cube_mesh(side)
    full = raster_cube(side, morph)
    grid = covering_grid(full, morph, mesh.bounds)
    layer, lines = 6, range(3, 6)
    gap = raster_cube(side, morph, skip=(layer, lines, 2.0, 6.0))
    q_full = inspect_deposit(deposit(full, morph, grid=grid), mesh.vertices, mesh.faces)
    dep = deposit(gap, morph, grid=grid)
    q_gap = inspect_deposit(dep, mesh.vertices, mesh.faces)
    assert q_gap.pore_ratio > q_full.pore_ratio + 0.002
    assert q_gap.infill_ratio < q_full.infill_ratio - 0.002
    # The new pores sit where the gap is.
    new = q_gap.pores & ~q_full.pores
    centre = grid.centers(np.argwhere(new)).mean(axis=0)
    z_gap = full.position[full.layer == layer, 2][0]
    w = full.width[0]
    expected = np.array([4.0, 4.5 * w, z_gap])
    assert np.all(np.abs(centre - expected) < [1.0, w, 2 * full.height[0]])


def test_bad_inputs() -> None:
    with pytest.raises(InputError):
        DepositionConfig(voxel_mm=0.0)
    line = _line(np.zeros(3), np.array([5.0, 0.0, 0.0]))
    with pytest.raises(InputError):
        deposit(_toolpath([line], [0], 0.0, 0.6, 1.5), EllipseMorphology())
    with pytest.raises(InputError):
        VoxelGrid.around(np.zeros(3), np.full(3, 1000.0), 0.05)


def test_chunking_keeps_the_volume_and_a_rerun_gives_the_same_deposit() -> None:
    morph = EllipseMorphology(beta=0.7)
    tp = raster_cube(4.0, morph)
    a = deposit(tp, morph)
    b = deposit(tp, morph, DepositionConfig(chunk_segments=7))
    c = deposit(tp, morph, DepositionConfig(chunk_segments=7))
    # The worker thread rasterising ahead does not make the result depend on timing.
    assert np.array_equal(b.fill, c.fill) and np.array_equal(b.layer, c.layer)
    assert a.grid == b.grid
    assert b.deposited_mm3 == pytest.approx(a.commanded_mm3, rel=1e-5)
    assert len(b.trace) > len(a.trace)
    # Splitting a layer only changes when its ink is spread, not how much there is.
    assert np.abs(a.fill - b.fill).sum() * a.grid.voxel_volume < 0.05 * a.commanded_mm3


def test_filaments_fuse_only_where_they_overlap() -> None:
    morph = EllipseMorphology()
    speed = 5.0
    w_f = float(morph.filament_size(np.array([speed]))[0][0])
    mid_fill = {}
    for spacing in (0.8 * w_f, 1.3 * w_f):
        a = _line(np.array([0.0, 0.0, 0.0]), np.array([8.0, 0.0, 0.0]))
        b = _line(np.array([8.0, spacing, 0.0]), np.array([0.0, spacing, 0.0]))
        dep = deposit(_toolpath([a, b], [0, 0], speed, 0.6, 1.0), morph,
                      DepositionConfig(voxel_mm=0.1))
        g = dep.grid
        i = np.abs(g.axis_centers(0) - 4.0).argmin()
        j = np.abs(g.axis_centers(1) - 0.5 * spacing).argmin()
        k = np.abs(g.axis_centers(2)).argmin()
        mid_fill[spacing > w_f] = float(dep.fill[i, j, k])
        assert dep.deposited_mm3 == pytest.approx(dep.commanded_mm3, rel=1e-5)
    assert mid_fill[False] > 0.99  # overlapping filaments merge into one body
    assert mid_fill[True] == 0.0  # apart, the gel between them stays


def test_center_offset_moves_the_filament_along_the_printing_direction() -> None:
    # +0.5 puts the filament's bottom at the nozzle tip (z = 0); the volume is unchanged.
    morph = EllipseMorphology(aspect=0.75)
    speed = 4.0
    tp = _toolpath([_line(np.zeros(3), np.array([8.0, 0.0, 0.0]))], [0], speed, 0.6, 1.5)
    dep = deposit(tp, morph, DepositionConfig(voxel_mm=0.1, center_offset=0.5))
    h_f = float(morph.filament_size(np.array([speed]))[1][0])
    solid = dep.fill >= 0.5
    zs = dep.grid.axis_centers(2)[solid.any(axis=(0, 1))]
    assert zs.min() == pytest.approx(0.0, abs=dep.grid.voxel)
    assert zs.max() == pytest.approx(h_f, abs=dep.grid.voxel)
    assert dep.deposited_mm3 == pytest.approx(dep.commanded_mm3, rel=1e-5)
    with pytest.raises(InputError):
        DepositionConfig(center_offset=0.8)
