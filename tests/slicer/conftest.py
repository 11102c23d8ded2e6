"""Tiny tet-mesh fixtures for the slicer tests: structured, deterministic, built in milliseconds."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from core.stages import TetMesh


def grid_tets(nx: int, ny: int, nz: int, periodic_y: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """A grid of nx*ny*nz index cells split into 6 tets each (Freudenthal split, conforming).

    Returns:
        (index coordinates (V, 3) float64, tets (T, 4) int64). With ``periodic_y`` the
        j = ny layer is identified with j = 0 (for a closed ring).
    """
    my = ny if periodic_y else ny + 1
    idx = np.arange((nx + 1) * my * (nz + 1)).reshape(nx + 1, my, nz + 1)
    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz),
                                              indexing="ij"))
    tets = []
    for perm in itertools.permutations(range(3)):
        c = [i.copy(), j.copy(), k.copy()]
        vs = [idx[c[0], c[1] % my, c[2]]]
        for ax in perm:
            c[ax] = c[ax] + 1
            vs.append(idx[c[0], c[1] % my, c[2]])
        tets.append(np.stack(vs, axis=1))
    coords = np.stack(np.meshgrid(np.arange(nx + 1), np.arange(my), np.arange(nz + 1),
                                  indexing="ij"), axis=-1).reshape(-1, 3).astype(np.float64)
    return coords, np.concatenate(tets)


def box_mesh(n: tuple[int, int, int] = (4, 4, 4), size: tuple[float, float, float] = (8, 8, 8),
             jitter: float = 0.0, seed: int = 0) -> TetMesh:
    """An axis-aligned box [0, size] in mm, optionally with interior vertices jittered."""
    coords, tets = grid_tets(*n)
    if jitter:
        inner = np.all((coords > 0) & (coords < np.array(n)), axis=1)
        rng = np.random.default_rng(seed)
        coords[inner] += rng.uniform(-jitter, jitter, size=(int(inner.sum()), 3))
    return TetMesh(coords * (np.array(size, dtype=float) / np.array(n)), tets)


def ring_mesh(nr: int = 2, nt: int = 32, nz: int = 10, r_in: float = 8.0, r_out: float = 10.0,
              height: float = 12.0, wave: float = 0.25) -> TetMesh:
    """A cylinder wall whose top rim is curved: z_top(theta) = height * (1 + wave cos theta)."""
    coords, tets = grid_tets(nr, nt, nz, periodic_y=True)
    r = r_in + (r_out - r_in) * coords[:, 0] / nr
    theta = 2 * np.pi * coords[:, 1] / nt
    z = coords[:, 2] / nz * height * (1.0 + wave * np.cos(theta))
    return TetMesh(np.column_stack([r * np.cos(theta), r * np.sin(theta), z]), tets)


@pytest.fixture(scope="session")
def box() -> TetMesh:
    """An 8 mm cube, 4^3 cells (384 tets), interior vertices jittered."""
    return box_mesh(jitter=0.3)


@pytest.fixture(scope="session")
def ring() -> TetMesh:
    """A 2 mm thick cylinder wall, 12 mm tall with a wavy (+-25 %) top rim."""
    return ring_mesh()
