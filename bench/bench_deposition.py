"""Benchmark: deposition of a ~500k-waypoint job at 0.25 mm (target <= 60 s).

By default a solid box printed with the planar, volume-matched, staggered raster (sim.baseline
in "volume" mode), sized so the toolpath has about ``--waypoints`` waypoints. With ``--job DIR``
a sliced job instead (its ``toolpath.npz`` and ``model.ply``; ``--layers A:B`` keeps layers
A to B-1): a curved layer's over-full voxels are a thin sheet in a large box, which the box
does not show (socket: see the README). Prints the stage timings, the volume check, the
metrics and the peak resident memory.

    .venv/bin/python bench/bench_deposition.py [--waypoints 500000] [--voxel 0.25] [--metrics]
    .venv/bin/python bench/bench_deposition.py --job out/socket --layers 100:120 --voxel 0.25
    .venv/bin/python bench/bench_deposition.py --job out/socket --voxel 0.25 \
        --max-voxels 300000000   # the whole socket: a 252 M-voxel grid, ~2.4 GB
"""

from __future__ import annotations

import argparse
import dataclasses
import resource
import time
from pathlib import Path

import numpy as np
import trimesh

from core.stages import Toolpath
from sim.baseline import PlanarConfig, planar_toolpath
from sim.deposition import DepositionConfig, EllipseMorphology, covering_grid, deposit
from sim.voxels import MAX_VOXELS


def _morphology():  # type: ignore[no-untyped-def]
    try:
        from slicer.extrusion import load_profile

        return load_profile("ecoflex-0030")
    except ImportError:
        return EllipseMorphology()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--waypoints", type=int, default=500_000)
    ap.add_argument("--voxel", type=float, default=0.25)
    ap.add_argument("--height", type=float, default=0.6, help="layer height, mm")
    ap.add_argument("--spacing", type=float, default=0.4, help="waypoint spacing, mm")
    ap.add_argument("--metrics", action="store_true", help="also time the quality metrics")
    ap.add_argument("--job", type=Path, help="a sliced job directory instead of the box")
    ap.add_argument("--layers", default="", metavar="A:B",
                    help="with --job: layers A to B-1 (--metrics then compares that part of "
                         "the print with the whole model)")
    ap.add_argument("--max-voxels", type=int, default=MAX_VOXELS,
                    help="largest grid (the default is the inspection's limit; the deposition "
                         "alone needs 8 bytes a voxel)")
    args = ap.parse_args()
    morph = _morphology()
    t0 = time.perf_counter()
    if args.job:
        vertices, faces, toolpath = _job(args.job, args.layers)
        width = float(np.median(toolpath.width))
        what = f"{args.job.name} layers {args.layers or 'all'}"
    else:
        cfg = PlanarConfig(layer_height_mm=args.height, beta=float(morph.beta),
                           width_mode="volume", perimeters=0, spacing_mm=args.spacing)
        # Size the cube for the requested waypoint count: N ~ S^3 / (H W spacing).
        probe = planar_toolpath(*_cube(10.0), morph, cfg)
        width = float(probe.width[0])
        side = (args.waypoints * args.height * width * args.spacing) ** (1.0 / 3.0)
        vertices, faces = _cube(side)
        toolpath = planar_toolpath(vertices, faces, morph, cfg)
        what = f"cube {side:.1f} mm"
    t_tp = time.perf_counter() - t0
    config = DepositionConfig(voxel_mm=args.voxel)
    t1 = time.perf_counter()
    grid = covering_grid(toolpath, morph, np.stack([vertices.min(0), vertices.max(0)]), config,
                         args.max_voxels)
    dep = deposit(toolpath, morph, config, grid=grid)
    t_dep = time.perf_counter() - t1
    print(f"job: {what}, {len(toolpath):,} waypoints, "
          f"{int(np.unique(toolpath.layer).size)} layers, W {width:.3f} mm, "
          f"H {toolpath.height[0]:.3f} mm, v {toolpath.speed[0]:.2f} mm/s")
    print(f"grid: {grid.shape} = {grid.size:,} voxels of {grid.voxel} mm")
    print(f"toolpath generation   {t_tp:8.2f} s")
    for name, sec in dep.timings.items():
        print(f"  deposition {name:<10} {sec:8.2f} s")
    print(f"deposition total      {t_dep:8.2f} s   (target <= 60 s)")
    print(f"volume: commanded {dep.commanded_mm3:.1f} mm^3, deposited {dep.deposited_mm3:.1f} "
          f"mm^3, error {100 * dep.volume_error:+.4f} %, status {dep.status}, "
          f"chunks {len(dep.trace)}, max passes {max(t.passes for t in dep.trace)}")
    if args.metrics:
        from sim.metrics import inspect_deposit

        t2 = time.perf_counter()
        q = inspect_deposit(dep, vertices, faces, toolpath)
        s = q.surface.stats()
        print(f"metrics               {time.perf_counter() - t2:8.2f} s: infill "
              f"{100 * q.infill_ratio:.2f} %, pores {100 * q.pore_ratio:.3f} %, over "
              f"{100 * q.over_deposition:.2f} %, surface error mean {s['mean']:.3f} p95 "
              f"{s['p95']:.3f} max {s['max']:.3f} mm")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f"peak memory (max RSS) {peak:8.0f} MB")


def _job(job_dir: Path, layers: str) -> tuple[np.ndarray, np.ndarray, Toolpath]:
    """The model surface and toolpath of a sliced job, optionally layers A:B only."""
    model = trimesh.load(job_dir / "model.ply", force="mesh", process=False)
    toolpath = Toolpath.load(job_dir)
    if layers:
        a, b = (int(x) for x in layers.split(":"))
        keep = (toolpath.layer >= a) & (toolpath.layer < b)
        n = len(toolpath.layer)
        toolpath = Toolpath(**{f.name: (v[keep] if isinstance(v, np.ndarray) and len(v) == n
                                        else v)
                               for f in dataclasses.fields(toolpath)
                               for v in [getattr(toolpath, f.name)]})
    return np.asarray(model.vertices), np.asarray(model.faces), toolpath


def _cube(side: float) -> tuple[np.ndarray, np.ndarray]:
    box = trimesh.creation.box(extents=[side, side, side])
    return np.asarray(box.vertices) + 0.5 * side, np.asarray(box.faces)


if __name__ == "__main__":
    main()
