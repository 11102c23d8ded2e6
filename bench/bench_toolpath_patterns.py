"""Benchmark: toolpath pattern stages on a ~20k-face curved annulus layer.

Times the width-driven deformation, the boundary distance (every backend), contours (eq. 9 and
the two-sided band fit), stripes and the Poisson alternative, and prints the measured width
error of each pattern (not volume matched: the spacing is W_mean for all).
Usage (from the repository root): .venv/bin/python bench/bench_toolpath_patterns.py
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from slicer.toolpath import (
    contours,
    deform,
    geodesic,
    poisson_stripes,
    stripes,
    surface,
    width_error,
)
from tests.slicer.toolpath.pattern_meshes import disc, dome, sliver_disc

BACKENDS = (("heat", True), ("heat", False), ("potpourri3d", True), ("igl", True), ("fmm", True))


def timed(fn: Callable[..., Any], *args: Any, **kwargs: Any) -> tuple[Any, float]:
    """Result and wall-clock seconds of one call."""
    start = time.perf_counter()
    result = fn(*args, **kwargs)
    return result, time.perf_counter() - start


def main() -> None:
    v, f = disc(45.0, 0.83, inner=12.0, jitter=0.2)
    v = dome(v, 15.0, 45.0)
    print("faces", len(f), "vertices", len(v))
    width = 1.2 + 0.02 * np.linalg.norm(v[:, :2], axis=1)
    res, dt = timed(deform.deform_to_constant_width, v, f, width, 30)
    print(f"deform 30 it   {dt:.2f} s  status {res.status}")
    for backend, robust in BACKENDS:
        _, dt = timed(geodesic.boundary_distance, res.vertices, f, backend=backend, robust=robust)
        print(f"geodesic {backend:12s} robust={robust!s:5s} {dt:.3f} s")
    d = geodesic.boundary_distance(res.vertices, f)
    w_mean = float(np.mean(width))
    lines_c, dt = timed(contours.contour_lines, res.vertices, f, d, w_mean)
    print(f"contours       {dt:.3f} s  lines {lines_c.n_lines}")
    loops = surface.boundary_loops(f)
    length = [float(np.linalg.norm(res.vertices[lp] - res.vertices[np.roll(lp, 1)],
                                   axis=1).sum()) for lp in loops]
    outer = int(np.argmax(length))
    inner = np.concatenate([lp for i, lp in enumerate(loops) if i != outer])
    start = time.perf_counter()
    d_out = geodesic.distance_from(res.vertices, f, loops[outer])
    d_in = geodesic.distance_from(res.vertices, f, inner)
    mass = surface.lumped_mass(res.vertices, f)
    heat = sp.diags(mass) + (2.0 * w_mean) ** 2 * surface.cotan_laplacian(res.vertices, f,
                                                                          robust=True)
    solve = surface.spd_solver(heat.tocsc())
    lines_t = contours.two_sided_contour_lines(res.vertices, f, d_out, d_in, w_mean,
                                               lambda u: np.asarray(solve(mass * u)))
    dt = time.perf_counter() - start
    print(f"two-sided      {dt:.3f} s  lines {lines_t.n_lines} (2 distances, smoother, lines)")
    z, dt = timed(surface.stripe_direction, res.vertices, f, d)
    print(f"direction      {dt:.3f} s")
    lines_s, dt = timed(stripes.stripe_lines, res.vertices, f, z, w_mean)
    print(f"stripes        {dt:.2f} s  lines {lines_s.n_lines}")
    lines_p, dt = timed(poisson_stripes.poisson_stripe_lines, res.vertices, f, z, w_mean)
    print(f"poisson        {dt:.3f} s  lines {lines_p.n_lines}")
    for name, lines in (("contour", lines_c), ("two-sided", lines_t), ("stripe", lines_s),
                        ("poisson", lines_p)):
        spacing, dt = timed(width_error.line_spacing, lines.points, lines.line, closed=lines.closed)
        error = width_error.width_error(spacing, w_mean)
        print(f"width error {name:8s} (deformed layer) {error}  [{dt:.3f} s]")
    vs, fs = sliver_disc(45.0, 0.6)
    exact = 45.0 - np.linalg.norm(vs[:, :2], axis=1)
    print("sliver disc faces", len(fs))
    for backend, robust in BACKENDS:
        d, dt = timed(geodesic.boundary_distance, vs, fs, backend=backend, robust=robust)
        err = float(np.abs(d - exact).max())
        print(f"  slivers {backend:12s} robust={robust!s:5s} {dt:.3f} s  max err {err:.3f} mm")


if __name__ == "__main__":
    main()
