"""Measure the SPD solver backends on a tet Laplacian (slicer/solvers.py picks by these).

Usage: .venv/bin/python bench/bench_solvers.py [N]   (N^3 grid cells, 6 tets each; default 36,
i.e. 279,936 tets and 50,653 vertices). Prints factor time, solve time for 3 right-hand sides,
residual and peak RSS per backend. Each backend runs in a fresh process so the memory
numbers do not mix.
"""

from __future__ import annotations

import itertools
import multiprocessing as mp
import resource
import sys
import time

import numpy as np
import scipy.sparse as sp


def grid_mesh(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A jittered n^3 grid of unit cubes split into 6 tets each (Freudenthal split)."""
    m = n + 1
    idx = np.arange(m**3).reshape(m, m, m)
    i, j, k = (a.ravel() for a in np.meshgrid(*(np.arange(n),) * 3, indexing="ij"))
    tets = []
    for perm in itertools.permutations(range(3)):
        c = [i.copy(), j.copy(), k.copy()]
        vs = [idx[c[0], c[1], c[2]]]
        for ax in perm:
            c[ax] = c[ax] + 1
            vs.append(idx[c[0], c[1], c[2]])
        tets.append(np.stack(vs, axis=1))
    grid = np.stack(np.meshgrid(*(np.arange(m),) * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    verts = grid + np.random.default_rng(seed).uniform(-0.2, 0.2, size=grid.shape)
    return verts.astype(np.float64), np.concatenate(tets)


def system(n: int) -> tuple[sp.csr_matrix, np.ndarray, int]:
    from core.stages import TetMesh
    from slicer.operators import build_operators

    verts, tets = grid_mesh(n)
    ops = build_operators(TetMesh(verts, tets))
    lap = ops.laplacian[1:, 1:]  # pin vertex 0: SPD
    b = np.random.default_rng(1).normal(size=(lap.shape[0], 3))
    return sp.csr_matrix(lap), b, len(tets)


def run(backend: str, n: int, queue: mp.Queue) -> None:
    from threadpoolctl import threadpool_limits

    threadpool_limits(1, "blas")  # as in slicer.field
    a, b, ntets = system(n)
    from slicer.solvers import SPDSolver

    c0, t0 = time.process_time(), time.perf_counter()
    s = SPDSolver(a, method=backend)  # type: ignore[arg-type]
    c1, t1 = time.process_time(), time.perf_counter()
    x, _ = s.solve(b)
    c2, t2 = time.process_time(), time.perf_counter()
    res = float(np.linalg.norm(a @ x - b) / np.linalg.norm(b))
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6  # process peak, GB
    queue.put((f"{backend}:{s.backend}", ntets, a.shape[0], t1 - t0, t2 - t1, c1 - c0, c2 - c1,
               res, rss))


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 36
    ctx = mp.get_context("spawn")
    print(f"{'backend':18s} {'tets':>8s} {'unknowns':>8s} {'setup s':>8s} {'solve3 s':>8s} "
          f"{'setupCPU':>8s} {'solveCPU':>8s} {'residual':>9s} {'peak GB':>8s}")
    for backend in ("cholespy", "splu", "amg"):
        q: mp.Queue = ctx.Queue()
        p = ctx.Process(target=run, args=(backend, n, q))
        p.start()
        p.join()
        name, nt, nu, tf, ts, cf, cs, res, rss = q.get()
        print(f"{name:18s} {nt:8d} {nu:8d} {tf:8.2f} {ts:8.3f} {cf:8.2f} {cs:8.3f} {res:9.1e} "
              f"{rss:8.2f}")


if __name__ == "__main__":
    main()
