"""The compiled deposition kernels against the dense operations they replace."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pytest
from scipy import ndimage

from sim import deposition_kernels as k
from sim.voxels import closing_cube

FULL, OVERFULL = 1.0 - 1e-5, 1.0 + 1e-5


def _sheet(seed: int, shape: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Over-full voxels (scattered, and a sheet as where a filament overlaps older ink), full
    voxels and voxels with room; returns (flat fill, over-full mask)."""
    rng = np.random.default_rng(seed)
    over = np.zeros(shape, dtype=bool)
    n = 40
    over[rng.integers(0, shape[0], n), rng.integers(0, shape[1], n),
         rng.integers(4, 8, n)] = True
    over[10:14, 5:15, 6] = True
    fill = np.where(rng.random(shape) < 0.7, 0.4, 1.0).astype(np.float32)
    fill[over] = 1.5
    return fill.reshape(-1), over


class _Mapped(NamedTuple):
    """The over-full voxels of a fill placed in a block map, with their regions."""

    src: np.ndarray
    table: np.ndarray
    pool: np.ndarray
    blocks: np.ndarray
    used: int
    current: np.ndarray
    parent: np.ndarray
    dirs: np.ndarray

    @staticmethod
    def of(fill: np.ndarray, over: np.ndarray, shape: tuple[int, int, int]) -> _Mapped:
        src = np.sort(np.flatnonzero(over))
        table = k.block_table(shape)
        pool = np.empty((table.size, 512), dtype=np.int32)
        blocks = np.empty(table.size, dtype=np.int64)
        used = k._place_sources(table, pool, blocks, src, *shape)
        current, parent, dirs = (np.empty(src.size, dtype=bool),
                                 np.empty(src.size, dtype=np.int64),
                                 np.empty(src.size, dtype=np.int64))
        k._regions(fill, src, OVERFULL, table, pool, *shape, current, parent, dirs, k._STEPS)
        return _Mapped(src, table, pool, blocks, used, current, parent, dirs)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_nearest_over_full_voxel_matches_the_feature_transform(seed: int) -> None:
    shape, reach = (30, 24, 12), 3
    fill, over = _sheet(seed, shape)
    m = _Mapped.of(fill, over, shape)
    src, ns, table, pool, blocks, used = m.src, m.src.size, m.table, m.pool, m.blocks, m.used
    dirs = m.dirs
    ids = k._IdArrays.new(ns + 8, src)  # tiny: the enumeration must resume after growing
    first, ncand, nid, ball = 0, 0, ns, k._ball(reach)
    while first < ns:
        first, used, ncand, nid = k._enumerate(
            first, fill, FULL, src, dirs, ball, k._direction_starts(ball), *shape, table, pool,
            blocks, used, 1,
            ids.vflat, ids.best, ids.owner, ids.stamp, ids.gap, ids.cand, ncand, nid)
        if first < ns:
            ids = ids.grown(nid + ball.shape[0])
    k._release(table, blocks, used)
    assert np.all(table == -1)
    cand = ids.cand[:ncand]
    got = dict(zip(ids.vflat[cand].tolist(), ids.best[cand].tolist(), strict=True))
    # The whole-box Euclidean feature transform.
    nearest = ndimage.distance_transform_edt(~over, return_distances=False, return_indices=True)
    room = fill.reshape(shape) < FULL
    idx = np.nonzero(room)
    want_own = np.stack([nearest[a][idx] for a in range(3)], axis=1)
    want_d2 = ((want_own - np.stack(idx, axis=1)) ** 2).sum(axis=1)
    keep = want_d2 <= reach**2
    want = dict(zip(np.ravel_multi_index(idx, shape)[keep].tolist(), want_d2[keep].tolist(),
                    strict=True))
    assert got == want  # the same voxels within reach, at the same distance
    own = np.unravel_index(src[ids.owner[cand]], shape)
    dst = np.unravel_index(ids.vflat[cand], shape)
    assert np.array_equal(((np.stack(own, 1) - np.stack(dst, 1)) ** 2).sum(axis=1),
                          ids.best[cand])  # paired with an over-full voxel at that distance


def test_regions_are_the_26_connected_components() -> None:
    shape = (30, 24, 12)
    fill, over = _sheet(4, shape)
    src = np.sort(np.flatnonzero(over))
    table = k.block_table(shape)
    pool = np.empty((table.size, 512), dtype=np.int32)
    blocks = np.empty(table.size, dtype=np.int64)
    used = k._place_sources(table, pool, blocks, src, *shape)
    ns = src.size
    current, parent, dirs = (np.empty(ns, dtype=bool), np.empty(ns, dtype=np.int64),
                             np.empty(ns, dtype=np.int64))
    k._regions(fill, src, OVERFULL, table, pool, *shape, current, parent, dirs, k._STEPS)
    k._release(table, blocks, used)
    roots = np.array([k._find(parent, i) for i in range(ns)])
    labels, _ = ndimage.label(over, structure=np.ones((3, 3, 3)))
    want = labels.reshape(-1)[src]
    # same partition: a root per label and a label per root
    assert len(set(zip(roots.tolist(), want.tolist(), strict=True))) == len(set(want.tolist()))
    assert len(set(roots.tolist())) == len(set(want.tolist()))
    assert np.all(dirs[over.reshape(-1)[src]] >= 0)


@pytest.mark.parametrize(("radius", "seed"), [(1, 0), (2, 1), (3, 2), (2, 3)])
def test_gap_flags_are_the_closing_of_the_ink(radius: int, seed: int) -> None:
    shape = (21, 19, 26)  # not multiples of the block: partial blocks at the far faces
    rng = np.random.default_rng(seed)
    ink = ndimage.binary_dilation(rng.random(shape) < 0.02, iterations=1)
    ink[:, :, :5] = True  # a floor reaching the grid's edge
    fill = np.where(ink, 0.8, 0.1).astype(np.float32).reshape(-1)
    cand = np.flatnonzero(fill < 2.0)
    rng.shuffle(cand)
    vflat = cand.copy()
    ids = np.arange(cand.size, dtype=np.int64)
    gap = np.full(cand.size, -1, dtype=np.int8)
    k._gap_flags(fill, ids, vflat, gap, radius, *shape)
    want = closing_cube(ink, radius).reshape(-1)[vflat]
    assert np.array_equal(gap.astype(bool), want)


def test_spread_conserves_ink_and_leaves_no_excess() -> None:
    shape = (30, 24, 12)
    fill, over = _sheet(5, shape)
    total = float(fill.sum(dtype=np.float64))
    tags = np.full(fill.size, -1, dtype=np.int32)
    table = k.block_table(shape)
    done = k.spread(fill, tags, shape, table, np.flatnonzero(over), 7, 2, 1, 6, FULL,
                    OVERFULL)
    assert np.all(table == -1)
    assert fill.sum(dtype=np.float64) == pytest.approx(total, rel=1e-6)
    assert done.residual < 1e-4 and fill.max() <= OVERFULL
    assert done.displaced == pytest.approx(0.5 * over.sum(), rel=1e-5)
    assert done.passes >= 1 and 0 < done.max_d2
    assert np.all(tags[fill.reshape(-1) != np.where(over.reshape(-1), 1.5, 0)] >= -1)
    assert np.any(tags == 7)


def test_counting_order_is_a_stable_sort() -> None:
    rng = np.random.default_rng(6)
    key = rng.integers(0, 9, 500)
    order = rng.permutation(500)
    got = k._counting_order(key, 9, order)
    assert np.array_equal(got, order[np.argsort(key[order], kind="stable")])


def test_add_ink_tags_the_voxels_that_gain_more_than_they_held() -> None:
    fill = np.array([0.0, 0.5, 0.9, 0.2], dtype=np.float32)
    tags = np.array([-1, 3, 3, 3], dtype=np.int32)
    k.add_ink(fill, tags, np.array([0, 1, 2]), np.array([0.2, 1.0, 0.1]), 2.0, 4)
    assert np.allclose(fill, [0.4, 2.5, 1.1, 0.2])
    assert tags.tolist() == [4, 4, 3, 3]


def test_a_closing_wider_than_the_kernels_handle_is_a_user_error() -> None:
    from core.errors import InputError
    from sim.deposition import DepositionConfig

    DepositionConfig(voxel_mm=0.04, gap_mm=1.0)  # radius 12 voxels: fine
    with pytest.raises(InputError, match="voxel of at least"):
        DepositionConfig(voxel_mm=0.02, gap_mm=1.0)


def test_excess_walled_in_by_full_voxels_goes_further_out() -> None:
    # An over-full voxel in a 9^3 block of full ink: no room within the first reach, so the
    # neighbourhood doubles until it reaches the gel around the block.
    shape = (21, 21, 21)
    fill = np.zeros(shape, dtype=np.float32)
    fill[6:15, 6:15, 6:15] = 1.0
    fill[10, 10, 10] = 3.0
    fill = fill.reshape(-1)
    total = float(fill.sum(dtype=np.float64))
    tags = np.full(fill.size, -1, dtype=np.int32)
    over = np.array([np.ravel_multi_index((10, 10, 10), shape)])
    done = k.spread(fill, tags, shape, k.block_table(shape), over, 1, 2, 1, 6, FULL, OVERFULL)
    assert done.residual < 1e-5 and fill.max() <= OVERFULL
    assert fill.sum(dtype=np.float64) == pytest.approx(total, rel=1e-6)
    assert done.max_d2 >= 5**2  # the nearest gel is 5 voxels away


def test_rasterise_keeps_the_volume_of_a_long_segment() -> None:
    # One 30 mm segment on a 0.1 mm grid: more distinct voxels than the first guess of the
    # output size, so the kernel resumes after growing its arrays.
    shape = (320, 24, 24)
    origin = np.array([-1.0, -1.2, -1.2])
    start = np.array([[0.0, 0.0, 0.0]])
    unit = np.array([[1.0, 0.0, 0.0]])
    lateral, up = np.array([[0.0, 1.0, 0.0]]), np.array([[0.0, 0.0, 1.0]])
    length, width, height = np.array([30.0]), np.array([1.2]), np.array([0.9])
    volume = np.pi / 4 * width * height * length
    vox = 0.1
    ext = np.array([[0.0, 0.6, 0.45]]) + 0.5 * vox
    vlo = np.ceil((start - ext - origin) / vox - 0.5).astype(np.int64)
    vhi = np.floor((start + unit * length[:, None] + ext - origin) / vox - 0.5).astype(np.int64)
    vlo, vhi = np.clip(vlo, 0, np.array(shape) - 1), np.clip(vhi, -1, np.array(shape) - 1)
    table = k.block_table(shape)
    flat, ink = k.rasterise(start, unit, lateral, up, length, width, height, volume, vlo, vhi,
                            vlo, origin, vox, shape, table)
    assert np.all(table == -1)
    assert np.unique(flat).size == flat.size > 4096
    assert ink.sum() == pytest.approx(volume[0], rel=1e-9)
    # no voxel holds more than itself; the inner ones are full
    assert ink.max() <= vox**3 * (1 + 1e-6)
    assert np.count_nonzero(ink > 0.99 * vox**3) * vox**3 < volume[0] < flat.size * vox**3


def test_a_later_pass_reassigns_voxels_whose_source_is_done() -> None:
    shape, reach = (30, 24, 12), 3
    fill, over = _sheet(7, shape)
    m = _Mapped.of(fill, over, shape)
    src, ns, table, pool, blocks, used = m.src, m.src.size, m.table, m.pool, m.blocks, m.used
    current, parent, dirs = m.current, m.parent, m.dirs
    ids = k._IdArrays.new(ns * 400, src)
    ball = k._ball(reach)
    _, used, ncand, _ = k._enumerate(
        0, fill, FULL, src, dirs, ball, k._direction_starts(ball), *shape, table, pool, blocks,
        used, 1, ids.vflat, ids.best, ids.owner, ids.stamp, ids.gap, ids.cand, 0, ns)
    done = src[::2]  # half the sources shed their excess
    fill[done] = 1.0
    k._regions(fill, src, OVERFULL, table, pool, *shape, current, parent, dirs, k._STEPS)
    kept = k._reassign(fill, FULL, src, current, k._by_distance(ball), *shape, table, pool,
                       ids.vflat, ids.best, ids.owner, ids.cand[:ncand])
    k._release(table, blocks, used)
    cand = ids.cand[:kept]
    still = over.copy().reshape(-1)
    still[done] = False
    still = still.reshape(shape)
    nearest = ndimage.distance_transform_edt(~still, return_distances=False,
                                             return_indices=True)
    room = np.flatnonzero(fill < FULL)
    own = np.stack([nearest[a].reshape(-1)[room] for a in range(3)], axis=1)
    d2 = ((own - np.stack(np.unravel_index(room, shape), axis=1)) ** 2).sum(axis=1)
    want = dict(zip(room[d2 <= reach**2].tolist(), d2[d2 <= reach**2].tolist(), strict=True))
    got = dict(zip(ids.vflat[cand].tolist(), ids.best[cand].tolist(), strict=True))
    assert got == want
    assert np.all(current[ids.owner[cand]])


def test_excess_with_no_room_anywhere_is_left_and_reported() -> None:
    shape = (40, 40, 40)
    fill = np.ones(shape, dtype=np.float32).reshape(-1)  # no room in the whole grid
    centre = np.ravel_multi_index((20, 20, 20), shape)
    fill[centre] = 3.0
    tags = np.full(fill.size, -1, dtype=np.int32)
    done = k.spread(fill, tags, shape, k.block_table(shape), np.array([centre]), 1, 2, 1, 6,
                    FULL, OVERFULL)
    assert done.residual == pytest.approx(2.0)
    assert fill[centre] == pytest.approx(3.0) and done.passes == 0
