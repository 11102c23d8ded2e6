"""Compiled kernels of the deposition simulation: rasterise a chunk of filaments, spread its
excess ink (the model is in ``sim.deposition``'s docstring).

A curved layer is a thin sheet in a large box: on the socket at 0.25 mm a layer's 70 k
over-full voxels lie in a box of 11.6 M. Dense array operations over the box (filters,
labelling, feature transforms) cost ~50 ns per box voxel, 90% of the time. These kernels visit
only the voxels near the sheet and key them through a sparse block map: the grid is split into
8^3-voxel blocks, a table (one int32 per block, ``block_table``) points to a row of 512 slots
allocated on first touch. A deposit keeps one table per thread; each call leaves it all -1 on
return, so a call costs what it touches, never the box.

All voxel indices are flat indices of the C-ordered ``(nx, ny, nz)`` grid.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

BLOCK_BITS = 3
BLOCK = 1 << BLOCK_BITS
_MASK = BLOCK - 1
_SLOTS = BLOCK**3


def block_table(shape: tuple[int, int, int]) -> NDArray[np.int32]:
    """(blocks,) int32, all -1: the block table of a grid of ``shape`` voxels."""
    n = 1
    for s in shape:
        n *= (int(s) + _MASK) >> BLOCK_BITS
    return np.full(n, -1, dtype=np.int32)


@njit(cache=True)
def _block(x: int, y: int, z: int, nby: int, nbz: int) -> int:
    return ((x >> BLOCK_BITS) * nby + (y >> BLOCK_BITS)) * nbz + (z >> BLOCK_BITS)


@njit(cache=True)
def _slot(x: int, y: int, z: int) -> int:
    return ((x & _MASK) << (2 * BLOCK_BITS)) | ((y & _MASK) << BLOCK_BITS) | (z & _MASK)


@njit(cache=True)
def _lookup(table: NDArray[np.int32], pool: NDArray[np.int32], x: int, y: int, z: int,
            nby: int, nbz: int) -> int:
    """The value stored for voxel (x, y, z), -1 if none."""
    row = table[_block(x, y, z, nby, nbz)]
    if row < 0:
        return -1
    return int(pool[row, _slot(x, y, z)])


@njit(cache=True)
def _row(table: NDArray[np.int32], pool: NDArray[np.int32], blocks: NDArray[np.int64],
         used: int, x: int, y: int, z: int, nby: int, nbz: int) -> tuple[int, int]:
    """(pool row of voxel (x, y, z)'s block, rows in use), allocating the row (all -1)."""
    b = _block(x, y, z, nby, nbz)
    row = table[b]
    if row < 0:
        row = used
        table[b] = row
        blocks[row] = b
        pool[row, :] = -1
        used += 1
    return int(row), used


@njit(cache=True)
def _release(table: NDArray[np.int32], blocks: NDArray[np.int64], used: int) -> None:
    for r in range(used):
        table[blocks[r]] = -1


def _segment_boxes(vlo: NDArray[np.int64], vhi: NDArray[np.int64]
                   ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Voxels and blocks of each segment's box (+1 for the fallback voxel), (S,) int64 each."""
    voxels = np.prod(np.maximum(vhi - vlo + 1, 0), axis=1) + 1
    blocks = np.prod(np.maximum((vhi >> BLOCK_BITS) - (vlo >> BLOCK_BITS) + 1, 0), axis=1) + 1
    return voxels, blocks


def rasterise(start: NDArray[np.float64], tangent: NDArray[np.float64],
              lateral: NDArray[np.float64], up: NDArray[np.float64],
              length: NDArray[np.float64], width: NDArray[np.float64],
              height: NDArray[np.float64], volume: NDArray[np.float64],
              vlo: NDArray[np.int64], vhi: NDArray[np.int64], mid: NDArray[np.int64],
              origin: NDArray[np.float64], vox: float, shape: tuple[int, int, int],
              table: NDArray[np.int32]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Ink of a chunk of segments, summed per voxel.

    Each segment's volume is shared over the voxels of its box ``[vlo, vhi]`` in proportion to
    the covered part of each voxel: exact along the segment (flat ends, so consecutive
    segments sum to 1), first-order signed distance across the ellipse. A segment covering no
    voxel (thinner than the grid resolves) puts its volume in ``mid``.

    Args:
        start, tangent, lateral, up: (S, 3) float64, the segments (``sim.deposition.Segments``).
        length, width, height, volume: (S,) float64, mm and mm^3.
        vlo, vhi: (S, 3) int64, inclusive voxel box of each segment (clipped to the grid).
        mid: (S, 3) int64, fallback voxel.
        origin: (3,) float64, mm, grid origin; vox: mm, voxel edge; shape: grid shape.
        table: the grid's block table (all -1; left so).

    Returns:
        (V,) int64 flat indices of the voxels that got ink, (V,) float64 their ink, mm^3.
    """
    n = start.shape[0]
    voxels, blocks_per = _segment_boxes(vlo, vhi)
    bound = int(min(blocks_per.sum(), table.size))
    pool = np.empty((bound, _SLOTS), dtype=np.int32)
    blocks = np.empty(bound, dtype=np.int64)
    # Distinct voxels are far fewer than the boxes' sum (neighbouring segments overlap): start
    # at a quarter of it and grow when a segment might not fit.
    cap = int(max(4096, min(voxels.sum() // 4, np.prod(shape))))
    flat = np.empty(cap, dtype=np.int64)
    acc = np.empty(cap, dtype=np.float64)
    first, used, count = 0, 0, 0
    try:
        while first < n:
            first, used, count = _rasterise_from(
                first, start, tangent, lateral, up, length, width, height, volume, vlo, vhi,
                mid, voxels, origin, vox, shape[0], shape[1], shape[2], table, pool, blocks,
                used, flat, acc, count)
            if first < n:
                cap = max(2 * cap, count + int(voxels[first]))
                flat = np.concatenate([flat, np.empty(cap - flat.size, dtype=np.int64)])
                acc = np.concatenate([acc, np.empty(cap - acc.size, dtype=np.float64)])
    finally:
        _release(table, blocks, used)
    return flat[:count].copy(), acc[:count].copy()


@njit(cache=True)
def _accumulate(table: NDArray[np.int32], pool: NDArray[np.int32], blocks: NDArray[np.int64],
                used: int, i: int, j: int, k: int, ny: int, nz: int, flat: NDArray[np.int64],
                acc: NDArray[np.float64], count: int, amount: float) -> tuple[int, int]:
    """Add ``amount`` to voxel (i, j, k)'s entry of ``acc`` (a new entry if it has none).

    Returns (pool rows in use, entries).
    """
    row, used = _row(table, pool, blocks, used, i, j, k, (ny + _MASK) >> BLOCK_BITS,
                     (nz + _MASK) >> BLOCK_BITS)
    slot = _slot(i, j, k)
    idx = pool[row, slot]
    if idx < 0:
        idx = count
        pool[row, slot] = idx
        flat[idx] = (i * ny + j) * nz + k
        acc[idx] = 0.0
        count += 1
    acc[idx] += amount
    return used, count


@njit(cache=True, nogil=True)
def _rasterise_from(first: int, start: NDArray[np.float64], tangent: NDArray[np.float64],
                    lateral: NDArray[np.float64], up: NDArray[np.float64],
                    length: NDArray[np.float64], width: NDArray[np.float64],
                    height: NDArray[np.float64], volume: NDArray[np.float64],
                    vlo: NDArray[np.int64], vhi: NDArray[np.int64], mid: NDArray[np.int64],
                    voxels: NDArray[np.int64], origin: NDArray[np.float64], vox: float,
                    nx: int, ny: int, nz: int, table: NDArray[np.int32],
                    pool: NDArray[np.int32], blocks: NDArray[np.int64], used: int,
                    flat: NDArray[np.int64], acc: NDArray[np.float64], count: int
                    ) -> tuple[int, int, int]:
    """``rasterise`` from segment ``first`` on, until a segment might not fit in ``flat``.

    Returns (the next segment, pool rows in use, voxels in ``flat``).
    """
    n = start.shape[0]
    for s in range(first, n):
        if count + voxels[s] > flat.size:
            return s, used, count
        t0, t1, t2 = tangent[s, 0], tangent[s, 1], tangent[s, 2]
        kb = 2.0 / width[s]
        ku = 2.0 / height[s]
        b0, b1, b2 = lateral[s, 0] * kb, lateral[s, 1] * kb, lateral[s, 2] * kb
        u0, u1, u2 = up[s, 0] * ku, up[s, 1] * ku, up[s, 2] * ku
        inv_ax = 2.0 * vox / width[s]
        inv_ay = 2.0 * vox / height[s]
        seg_len = length[s] / vox
        # Two sweeps: the coverage sum, then the shares (cheaper than storing the coverages).
        share = 0.0
        for sweep in range(2):
            total = 0.0
            for i in range(vlo[s, 0], vhi[s, 0] + 1):
                dx = origin[0] + (i + 0.5) * vox - start[s, 0]
                for j in range(vlo[s, 1], vhi[s, 1] + 1):
                    dy = origin[1] + (j + 0.5) * vox - start[s, 1]
                    for k in range(vlo[s, 2], vhi[s, 2] + 1):
                        dz = origin[2] + (k + 0.5) * vox - start[s, 2]
                        along = (dx * t0 + dy * t1 + dz * t2) / vox
                        cov = min(along + 0.5, seg_len) - max(along - 0.5, 0.0)
                        if cov <= 0.0:
                            continue
                        cov = min(cov, 1.0)
                        x = dx * b0 + dy * b1 + dz * b2
                        y = dx * u0 + dy * u1 + dz * u2
                        rho = np.sqrt(x * x + y * y)
                        grad = np.sqrt((x * inv_ax) ** 2 + (y * inv_ay) ** 2)
                        dist = (rho - 1.0) * rho / max(grad, 1e-6)  # voxels, < 0 inside
                        cov *= min(max(0.5 - dist, 0.0), 1.0)
                        if cov <= 0.0:
                            continue
                        if sweep == 0:
                            total += cov
                            continue
                        used, count = _accumulate(table, pool, blocks, used, i, j, k, ny, nz,
                                                  flat, acc, count, share * cov)
            if sweep == 0:
                if total <= 1e-9:
                    break
                share = volume[s] / total
        if share == 0.0:
            used, count = _accumulate(table, pool, blocks, used, mid[s, 0], mid[s, 1],
                                      mid[s, 2], ny, nz, flat, acc, count, volume[s])
    return n, used, count


@njit(cache=True, nogil=True)
def add_ink(fill: NDArray[np.float32], tags: NDArray[np.int32], flat: NDArray[np.int64],
            volume: NDArray[np.float64], per_mm3: float, layer: int) -> None:
    """Add ``volume`` (mm^3, times ``per_mm3`` = 1 / voxel volume) to the voxels ``flat`` of
    ``fill``; a voxel gaining more than it held is tagged ``layer`` (in one pass: the scattered
    reads and writes of a large grid cost more than the arithmetic)."""
    for c in range(flat.size):
        v = flat[c]
        add = np.float32(volume[c] * per_mm3)
        if add > fill[v]:
            tags[v] = layer
        fill[v] += add


@njit(cache=True)
def _ball(reach: int) -> NDArray[np.int64]:
    """(K, 5) int64: offsets (dx, dy, dz, squared length, direction) within ``reach`` voxels,
    by direction = the index of (sign dx, sign dy, sign dz) among the 27 neighbours."""
    side = 2 * reach + 1
    out = np.empty((side * side * side, 5), dtype=np.int64)
    n = 0
    r2 = reach * reach
    for dx in range(-reach, reach + 1):
        for dy in range(-reach, reach + 1):
            for dz in range(-reach, reach + 1):
                d2 = dx * dx + dy * dy + dz * dz
                if d2 <= r2:
                    out[n, 0], out[n, 1], out[n, 2], out[n, 3] = dx, dy, dz, d2
                    out[n, 4] = (np.sign(dx) + 1) * 9 + (np.sign(dy) + 1) * 3 + np.sign(dz) + 1
                    n += 1
    # Grouped by direction (the order within a group stays z fastest).
    return out[:n][np.argsort(out[:n, 4], kind="mergesort")]


@njit(cache=True)
def _direction_starts(ball: NDArray[np.int64]) -> NDArray[np.int64]:
    """(28,) int64: the rows of ``ball`` in direction d are ``starts[d]:starts[d + 1]``."""
    starts = np.zeros(28, dtype=np.int64)
    for o in range(ball.shape[0]):
        starts[ball[o, 4] + 1] += 1
    return np.cumsum(starts)


@njit(cache=True)
def _by_distance(ball: NDArray[np.int64]) -> NDArray[np.int64]:
    """``ball``'s rows, nearest first."""
    return ball[np.argsort(ball[:, 3], kind="mergesort")]


@njit(cache=True)
def _find(parent: NDArray[np.int64], i: int) -> int:
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:  # path compression
        nxt = parent[i]
        parent[i] = root
        i = nxt
    return root


@njit(cache=True, nogil=True)
def _place_sources(table: NDArray[np.int32], pool: NDArray[np.int32],
                   blocks: NDArray[np.int64], src: NDArray[np.int64], nx: int, ny: int,
                   nz: int) -> int:
    """Give the sources the ids 0..n-1 in the map; returns the rows in use."""
    nby = (ny + _MASK) >> BLOCK_BITS
    nbz = (nz + _MASK) >> BLOCK_BITS
    used = 0
    for i in range(src.size):
        x, y, z = src[i] // (ny * nz), (src[i] // nz) % ny, src[i] % nz
        row, used = _row(table, pool, blocks, used, x, y, z, nby, nbz)
        pool[row, _slot(x, y, z)] = i
    return used


def _direction_steps() -> NDArray[np.int64]:
    """(27,) int64: for each direction, the bits of its steps (the non-zero directions s with
    s_a in {0, d_a}); 0 for the centre."""
    out = np.zeros(27, dtype=np.int64)
    signs = [(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)]
    for d, (a, b, c) in enumerate(signs):
        for sa in {0, a}:
            for sb in {0, b}:
                for sc in {0, c}:
                    if (sa, sb, sc) != (0, 0, 0):
                        out[d] |= 1 << ((sa + 1) * 9 + (sb + 1) * 3 + sc + 1)
    return out


_STEPS = _direction_steps()


@njit(cache=True, nogil=True)
def _regions(fill: NDArray[np.float32], src: NDArray[np.int64], overfull: float,
             table: NDArray[np.int32], pool: NDArray[np.int32], nx: int, ny: int, nz: int,
             current: NDArray[np.bool_], parent: NDArray[np.int64],
             open_dirs: NDArray[np.int64], steps: NDArray[np.int64]) -> None:
    """Which sources are over-full now (``current``), their 26-connected regions (union-find
    ``parent``) and the directions in which each has a neighbour that is not over-full.

    A voxel v is nearer to every neighbour u + s of u with s a step towards v (s_a in
    {0, sign(v_a - u_a)}, s != 0) than to u, so u can be the nearest over-full voxel of v only
    if none of those neighbours is over-full: on a sheet only the columns straight out of its
    faces, not the whole ball (``open_dirs``: bit (dx + 1) * 9 + (dy + 1) * 3 + dz + 1 for the
    directions whose steps are all free; a step out of the grid counts as free, v is then
    outside too).
    """
    nby = (ny + _MASK) >> BLOCK_BITS
    nbz = (nz + _MASK) >> BLOCK_BITS
    ns = src.size
    for i in range(ns):
        current[i] = fill[src[i]] > overfull
        parent[i] = i
        open_dirs[i] = 0
    for i in range(ns):
        if not current[i]:
            continue
        x, y, z = src[i] // (ny * nz), (src[i] // nz) % ny, src[i] % nz
        free = 0
        for dx in range(-1, 2):
            a = x + dx
            for dy in range(-1, 2):
                b = y + dy
                for dz in range(-1, 2):
                    d = z + dz
                    if dx == 0 and dy == 0 and dz == 0:
                        continue
                    bit = 1 << ((dx + 1) * 9 + (dy + 1) * 3 + dz + 1)
                    if a < 0 or a >= nx or b < 0 or b >= ny or d < 0 or d >= nz:
                        free |= bit
                        continue
                    j = _lookup(table, pool, a, b, d, nby, nbz)
                    if 0 <= j < ns and current[j]:
                        ri, rj = _find(parent, i), _find(parent, j)
                        if ri != rj:
                            parent[max(ri, rj)] = min(ri, rj)
                    else:
                        free |= bit
        usable = 0
        for d in range(27):
            if (free & steps[d]) == steps[d] and steps[d] != 0:
                usable |= 1 << d
        open_dirs[i] = usable


@njit(cache=True)
def _open_offsets(dirs: int, starts: NDArray[np.int64], out: NDArray[np.int64]) -> int:
    """Write the ball rows of the directions set in ``dirs`` to ``out``; returns how many."""
    n = 0
    for d in range(27):
        if (dirs >> d) & 1:
            for o in range(starts[d], starts[d + 1]):
                out[n] = o
                n += 1
    return n


@njit(cache=True, nogil=True)
def _enumerate(first: int, fill: NDArray[np.float32], full: float, src: NDArray[np.int64],
               open_dirs: NDArray[np.int64], ball: NDArray[np.int64],
               starts: NDArray[np.int64], nx: int, ny: int, nz: int,
               table: NDArray[np.int32], pool: NDArray[np.int32],
               blocks: NDArray[np.int64], used: int, sweep: int, vflat: NDArray[np.int64],
               best: NDArray[np.int64], owner: NDArray[np.int64], stamp: NDArray[np.int64],
               gap: NDArray[np.int8], cand: NDArray[np.int64], ncand: int, nid: int
               ) -> tuple[int, int, int, int]:
    """The voxels with room within the ball of each source from ``first`` on, each with its
    nearest source (``owner``, squared distance ``best``), listed once per ``sweep`` in
    ``cand``; stops before a source whose ball might not fit in the id arrays.

    Returns (the next source, rows in use, candidates, ids).
    """
    nby = (ny + _MASK) >> BLOCK_BITS
    nbz = (nz + _MASK) >> BLOCK_BITS
    room = ball.shape[0]
    rows = np.empty(room, dtype=np.int64)
    for i in range(first, src.size):
        dirs = open_dirs[i]
        if dirs == 0:
            continue
        if nid + room > vflat.size:
            return i, used, ncand, nid
        x, y, z = src[i] // (ny * nz), (src[i] // nz) % ny, src[i] % nz
        for t in range(_open_offsets(dirs, starts, rows)):
            o = rows[t]
            a, b, d = x + ball[o, 0], y + ball[o, 1], z + ball[o, 2]
            if a < 0 or a >= nx or b < 0 or b >= ny or d < 0 or d >= nz:
                continue
            v = (a * ny + b) * nz + d
            if fill[v] >= full:
                continue
            row, used = _row(table, pool, blocks, used, a, b, d, nby, nbz)
            slot = _slot(a, b, d)
            idx = pool[row, slot]
            if idx < 0:
                idx = nid
                pool[row, slot] = idx
                vflat[idx] = v
                stamp[idx] = -1
                gap[idx] = -1
                nid += 1
            if stamp[idx] != sweep:
                stamp[idx] = sweep
                best[idx] = ball[o, 3]
                owner[idx] = i
                cand[ncand] = idx
                ncand += 1
            elif ball[o, 3] < best[idx]:
                best[idx] = ball[o, 3]
                owner[idx] = i
    return src.size, used, ncand, nid


@njit(cache=True, nogil=True)
def _reassign(fill: NDArray[np.float32], full: float, src: NDArray[np.int64],
              current: NDArray[np.bool_], ball: NDArray[np.int64], nx: int, ny: int, nz: int,
              table: NDArray[np.int32], pool: NDArray[np.int32], vflat: NDArray[np.int64],
              best: NDArray[np.int64], owner: NDArray[np.int64], cand: NDArray[np.int64]
              ) -> int:
    """The candidates of the previous sweep for a later pass, in place; returns how many.

    Between passes voxels only lose room and sources only stop being over-full, so the
    voxels with room near the sources now are among the previous ones, and a voxel whose
    nearest source is still over-full keeps it (nearest among fewer). The others look for
    their nearest source in ``ball`` (nearest first) or drop out.
    """
    nby = (ny + _MASK) >> BLOCK_BITS
    nbz = (nz + _MASK) >> BLOCK_BITS
    ns = src.size
    kept = 0
    for c in range(cand.size):
        idx = cand[c]
        v = vflat[idx]
        if fill[v] >= full:
            continue
        if not current[owner[idx]]:
            x, y, z = v // (ny * nz), (v // nz) % ny, v % nz
            found = -1
            for o in range(ball.shape[0]):
                a, b, d = x + ball[o, 0], y + ball[o, 1], z + ball[o, 2]
                if a < 0 or a >= nx or b < 0 or b >= ny or d < 0 or d >= nz:
                    continue
                j = _lookup(table, pool, a, b, d, nby, nbz)
                if 0 <= j < ns and current[j]:
                    found = o
                    owner[idx] = j
                    best[idx] = ball[o, 3]
                    break
            if found < 0:
                continue
        cand[kept] = idx
        kept += 1
    return kept


@njit(cache=True, nogil=True, parallel=True)
def _gap_flags(fill: NDArray[np.float32], cand: NDArray[np.int64], vflat: NDArray[np.int64],
               gap: NDArray[np.int8], radius: int, nx: int, ny: int, nz: int) -> None:
    """Set ``gap`` (1 or 0) where it is unset (-1): whether a morphological closing of the ink
    (f >= 0.5) by a (2 radius + 1)^3 cube fills the voxel (outside the grid counts as empty,
    as in ``sim.voxels.closing_cube``). Blocks in parallel (``_close_block``).
    """
    nby = (ny + _MASK) >> BLOCK_BITS
    nbz = (nz + _MASK) >> BLOCK_BITS
    todo = np.empty(cand.size, dtype=np.int64)
    m = 0
    for c in range(cand.size):
        if gap[cand[c]] < 0:
            todo[m] = cand[c]
            m += 1
    if m == 0:
        return
    key = np.empty(m, dtype=np.int64)
    for t in range(m):
        v = vflat[todo[t]]
        key[t] = _block(v // (ny * nz), (v // nz) % ny, v % nz, nby, nbz)
    order = _counting_order(key, ((nx + _MASK) >> BLOCK_BITS) * nby * nbz, np.arange(m))
    starts = np.empty(m + 1, dtype=np.int64)
    groups = 0
    for t in range(m):
        if t == 0 or key[order[t]] != key[order[t - 1]]:
            starts[groups] = t
            groups += 1
    starts[groups] = m
    for g in prange(groups):
        _close_block(fill, key[order[starts[g]]], todo, order[starts[g]:starts[g + 1]], vflat,
                     gap, radius, nx, ny, nz, nby, nbz)


@njit(cache=True, nogil=True)
def _close_block(fill: NDArray[np.float32], block: int, todo: NDArray[np.int64],
                 members: NDArray[np.int64], vflat: NDArray[np.int64], gap: NDArray[np.int8],
                 r: int, nx: int, ny: int, nz: int, nby: int, nbz: int) -> None:
    """The gap flags of the voxels ``todo[members]``, all in ``block``.

    The ink of the block and its 2 r margin, one bit per voxel along z (8 + 4 r <= 62 bits),
    dilated then eroded with shifts (z) and neighbouring columns (x, y).
    """
    side = BLOCK + 4 * r
    bits = (1 << side) - 1
    ink = np.zeros((side, side), dtype=np.int64)
    grown = np.zeros((side, side), dtype=np.int64)
    work = np.zeros((side, side), dtype=np.int64)
    x0 = (block // (nby * nbz)) * BLOCK - 2 * r
    y0 = ((block // nbz) % nby) * BLOCK - 2 * r
    z0 = (block % nbz) * BLOCK - 2 * r
    klo, khi = max(0, -z0), min(side, nz - z0)
    inside_z = 0
    for k in range(klo, khi):
        inside_z |= 1 << k
    for i in range(max(0, -x0), min(side, nx - x0)):
        for j in range(max(0, -y0), min(side, ny - y0)):
            base = ((x0 + i) * ny + y0 + j) * nz + z0
            mask = 0
            for k in range(klo, khi):
                if fill[base + k] >= 0.5:
                    mask |= 1 << k
            ink[i, j] = mask
    # Dilation: z by shifts, then y, then x by neighbouring columns.
    for i in range(side):
        for j in range(side):
            mask = ink[i, j]
            out = mask
            for s in range(1, r + 1):
                out |= (mask << s) | (mask >> s)
            work[i, j] = out & bits
    for i in range(side):
        for j in range(r, side - r):
            out = 0
            for s in range(-r, r + 1):
                out |= work[i, j + s]
            grown[i, j] = out
    for i in range(r, side - r):
        for j in range(r, side - r):
            out = 0
            for s in range(-r, r + 1):
                out |= grown[i + s, j]
            # Outside the grid counts as empty for the erosion too.
            if 0 <= x0 + i < nx and 0 <= y0 + j < ny:
                work[i, j] = out & inside_z
            else:
                work[i, j] = 0
    # Erosion of the core's neighbourhood: x by neighbouring columns here, then y and z per
    # voxel.
    for i in range(2 * r, side - 2 * r):
        for j in range(r, side - r):
            out = bits
            for s in range(-r, r + 1):
                out &= work[i + s, j]
            grown[i, j] = out
    for t in members:
        c = todo[t]
        v = vflat[c]
        i = v // (ny * nz) - x0
        j = (v // nz) % ny - y0
        k = v % nz - z0
        out = bits
        for s in range(-r, r + 1):
            out &= grown[i, j + s]
        closed = out
        for s in range(1, r + 1):
            closed &= (out << s) & (out >> s)
        gap[c] = (closed >> k) & 1


@njit(cache=True)
def _counting_order(key: NDArray[np.int64], size: int, order: NDArray[np.int64]
                    ) -> NDArray[np.int64]:
    """``order`` stably re-sorted by ``key[order]`` (integers in [0, size))."""
    count = np.zeros(size + 1, dtype=np.int64)
    for c in order:
        count[key[c] + 1] += 1
    for k in range(size):
        count[k + 1] += count[k]
    out = np.empty(order.size, dtype=np.int64)
    for c in order:
        out[count[key[c]]] = c
        count[key[c]] += 1
    return out


@njit(cache=True, nogil=True)
def _fill_pass(fill: NDArray[np.float32], tags: NDArray[np.int32], layer: int,
               src: NDArray[np.int64], current: NDArray[np.bool_], parent: NDArray[np.int64],
               room: NDArray[np.int64], vflat: NDArray[np.int64], best: NDArray[np.int64],
               owner: NDArray[np.int64], gap: NDArray[np.int8], tiers: bool, reach: int
               ) -> tuple[bool, float, int]:
    """One pass: each region's excess into its voxels with room, gaps first (``tiers``),
    nearest first; the sources give up what was placed, in proportion to their excess.

    Returns (whether any ink moved, the excess at the start in voxel fractions, the largest
    squared distance ink moved, voxels^2).
    """
    ns = src.size
    region = np.full(ns, -1, dtype=np.int64)
    nreg = 0
    for i in range(ns):
        if current[i]:
            root = _find(parent, i)
            if region[root] < 0:  # the root is the smallest index of its region
                region[root] = nreg
                nreg += 1
            region[i] = region[root]
    excess = np.zeros(ns, dtype=np.float64)
    region_excess = np.zeros(nreg, dtype=np.float64)
    for i in range(ns):
        if current[i]:
            excess[i] = float(fill[src[i]]) - 1.0
            region_excess[region[i]] += excess[i]
    r2 = reach * reach
    rank = np.empty(room.size, dtype=np.int64)
    group = np.empty(room.size, dtype=np.int64)
    for c in range(room.size):
        idx = room[c]
        tier = 1 if tiers and gap[idx] != 1 else 0
        rank[c] = tier * (r2 + 1) + best[idx]
        group[c] = region[owner[idx]]
    # By region, then gaps first, then nearest first: two stable counting sorts (the keys are
    # small integers), cheaper than a comparison sort of a few 100 k candidates.
    order = _counting_order(group, nreg, _counting_order(rank, 2 * (r2 + 1),
                                                          np.arange(room.size)))
    placed = np.zeros(nreg, dtype=np.float64)
    moved = False
    max_d2 = 0
    for c in range(room.size):
        idx = room[order[c]]
        r = region[owner[idx]]
        want = region_excess[r] - placed[r]
        if want <= 0.0:
            continue
        v = vflat[idx]
        take = min(want, 1.0 - float(fill[v]))
        if take <= 0.0:
            continue
        placed[r] += take
        gained = np.float32(take)
        if gained > fill[v]:
            tags[v] = layer
        fill[v] += gained
        moved = True
        max_d2 = max(max_d2, best[idx])
    if moved:
        for i in range(ns):
            if current[i] and region_excess[region[i]] > 0.0:
                fill[src[i]] -= np.float32(excess[i] * placed[region[i]]
                                           / region_excess[region[i]])
    return moved, region_excess.sum(), max_d2


class Spread(NamedTuple):
    """What ``spread`` did (volumes in voxel fractions).

    displaced: float, excess of the over-full voxels before spreading.
    passes: int, passes that placed ink.
    max_d2: int, voxels^2, largest squared distance ink was moved.
    residual: float, excess left in over-full voxels (0 unless no room was found).
    """

    displaced: float
    passes: int
    max_d2: int
    residual: float


def spread(fill: NDArray[np.float32], tags: NDArray[np.int32], shape: tuple[int, int, int],
           table: NDArray[np.int32], over: NDArray[np.int64], layer: int, reach: int,
           closing: int, max_passes: int, full: float, overfull: float) -> Spread:
    """Push the excess ink of over-full voxels into nearby voxels with room (in place).

    The over-full voxels form 26-connected regions (where a new filament overlaps older ink).
    Each voxel with room within ``reach`` of an over-full voxel belongs to the region of its
    nearest over-full voxel (Euclidean). A region's excess fills its voxels nearest first;
    gaps and grooves of the ink (voxels a morphological closing of the ink, f >= 0.5, by a
    (2 closing + 1)^3 cube fills) come first: the first pass offers them only, later passes all
    room, gaps before open gel. What a region cannot place goes on in another pass (at most
    ``max_passes``); when the neighbourhood runs out of room ``reach`` doubles, up to
    ``MAX_REACH`` voxels and ``MAX_BALL_VISITS``; excess still without room is left in place
    and returned as ``residual``. Voxels gaining more ink than they held are tagged ``layer``.

    Args:
        fill: (nx * ny * nz,) float32, ink fraction, updated in place; tags: (same,) int32.
        shape: (nx, ny, nz); table: the grid's block table (all -1; left so).
        over: (n,) int64, voxels that may be over-full (those above ``overfull`` are).
        reach: voxels; closing: voxels (0 = no wetting of gaps), at most 13.
        full: a voxel has room below this fill; overfull: it must shed ink above this.
    """
    nx, ny, nz = shape
    if not 0 <= closing <= MAX_CLOSING:
        raise ValueError(f"closing radius {closing} is outside 0..{MAX_CLOSING} voxels")
    # Sorted: neighbouring sources then visit neighbouring memory.
    src = np.sort(over[fill[over] > overfull])
    displaced: float | None = None
    passes = 0
    max_d2 = 0
    diag = int(np.ceil(np.sqrt(float(nx * nx + ny * ny + nz * nz))))
    nby, nbz = (ny + _MASK) >> BLOCK_BITS, (nz + _MASK) >> BLOCK_BITS
    while src.size:
        ns = src.size
        ball = _ball(reach)
        near_first = _by_distance(ball)
        starts = _direction_starts(ball)
        src_blocks = np.unique(((src // (ny * nz)) >> BLOCK_BITS) * nby * nbz
                               + (((src // nz) % ny) >> BLOCK_BITS) * nbz
                               + ((src % nz) >> BLOCK_BITS)).size
        grow = (reach + _MASK) >> BLOCK_BITS
        bound = int(min(src_blocks * (2 * grow + 1) ** 3, table.size))
        pool = np.empty((bound, _SLOTS), dtype=np.int32)
        blocks = np.empty(bound, dtype=np.int64)
        used = 0
        try:
            used = _place_sources(table, pool, blocks, src, nx, ny, nz)
            # A source's ball lists a few voxels with room (a sheet: the columns off its faces).
            ids = _IdArrays.new(max(4096, 8 * ns), src)
            nid, ncand = ns, 0
            sweep = 0
            wetting = closing > 0
            passes_here = 0
            current = np.empty(ns, dtype=np.bool_)
            parent = np.empty(ns, dtype=np.int64)
            open_dirs = np.empty(ns, dtype=np.int64)
            for _ in range(max_passes):
                if not np.any(fill[src] > overfull):
                    break
                _regions(fill, src, overfull, table, pool, nx, ny, nz, current, parent,
                         open_dirs, _STEPS)
                orphans = 0
                if sweep:
                    prev = ids.cand[:ncand]
                    orphans = int(np.count_nonzero(~current[ids.owner[prev]]))
                # A later pass re-uses the last candidates (``_reassign``) unless finding new
                # owners for those whose owner is done costs more than sweeping again.
                if sweep == 0 or orphans > np.count_nonzero(open_dirs):
                    sweep, first, ncand = sweep + 1, 0, 0
                    while True:
                        first, used, ncand, nid = _enumerate(
                            first, fill, full, src, open_dirs, ball, starts, nx, ny, nz,
                            table, pool, blocks, used, sweep, ids.vflat, ids.best, ids.owner,
                            ids.stamp, ids.gap, ids.cand, ncand, nid)
                        if first == ns:
                            break
                        ids = ids.grown(nid + ball.shape[0])
                else:
                    ncand = _reassign(fill, full, src, current, near_first, nx, ny, nz, table,
                                      pool, ids.vflat, ids.best, ids.owner, ids.cand[:ncand])
                cand = ids.cand[:ncand]
                if closing > 0:
                    # On the ink before any spreading in this neighbourhood: every later
                    # candidate is met in the first sweep (room and sources only shrink).
                    _gap_flags(fill, cand, ids.vflat, ids.gap, closing, nx, ny, nz)
                room = cand[ids.gap[cand] == 1] if wetting and passes_here == 0 else cand
                if room.size == 0:
                    if wetting:
                        wetting = False
                        continue
                    break
                passes += 1
                passes_here += 1
                moved, excess, d2 = _fill_pass(fill, tags, layer, src, current, parent, room,
                                               ids.vflat, ids.best, ids.owner, ids.gap,
                                               closing > 0, reach)
                if displaced is None:
                    displaced = excess
                if not moved:
                    if wetting:
                        wetting = False
                        continue
                    break
                max_d2 = max(max_d2, d2)
        finally:
            _release(table, blocks, used)
        src = src[fill[src] > overfull]
        wider = min(2 * reach, diag)
        # The ball grows with the cube of the reach: stop at a bounded cost and report what
        # is left (a pathological job, e.g. ink walled in by ink over centimetres).
        if (src.size == 0 or wider == reach or wider > MAX_REACH
                or src.size * 4.2 * wider**3 > MAX_BALL_VISITS):
            break
        reach = wider
    ink = fill[over]
    residual = float(np.clip(ink - 1.0, 0.0, None).sum(dtype=np.float64))
    return Spread(displaced or 0.0, passes, max_d2, residual)


# The closing's bit columns hold a block and twice its margin on each side: 8 + 4 r <= 62.
MAX_CLOSING = 13
# How far a neighbourhood may grow (voxels), and the ball visits a growth may cost.
MAX_REACH = 64
MAX_BALL_VISITS = 300_000_000


class _IdArrays(NamedTuple):
    """Per-voxel records of a neighbourhood, by id (ids 0..ns-1 are the sources).

    vflat: flat voxel index; best: squared distance to the nearest source; owner: that source;
    stamp: the sweep that last listed the voxel; gap: 1/0 gap flag, -1 unknown; cand: the
    ids listed in the current sweep.
    """

    vflat: NDArray[np.int64]
    best: NDArray[np.int64]
    owner: NDArray[np.int64]
    stamp: NDArray[np.int64]
    gap: NDArray[np.int8]
    cand: NDArray[np.int64]

    @staticmethod
    def new(cap: int, src: NDArray[np.int64]) -> _IdArrays:
        def i64() -> NDArray[np.int64]:
            return np.empty(cap, dtype=np.int64)

        out = _IdArrays(i64(), i64(), i64(), i64(), np.empty(cap, dtype=np.int8), i64())
        out.vflat[: src.size] = src
        out.stamp[: src.size] = -1
        out.gap[: src.size] = -1
        return out

    def grown(self, need: int) -> _IdArrays:
        cap = max(2 * self.vflat.size, need)
        return _IdArrays(*(np.concatenate([a, np.empty(cap - a.size, dtype=a.dtype)])
                           for a in self))
