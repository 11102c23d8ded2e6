"""Benchmark: one change at a time, from a sliced job's tet mesh and field to its virtual print.

For each variant the layers are extracted from DIR's ``tetmesh.npz`` and ``field.npz`` (so
fTetWild's run-to-run differences stay out), then the toolpath, the flush, the deposition and
the metrics run as ``mesp slice`` and ``mesp inspect`` would. The variants:

* ``deformation``: the width deformation run to its tolerance (the defaults) against a fixed
  6 iterations (before session 10).
* ``slab-heights``: layer heights matched to the exact slab volumes (``slicer.slabs``, the
  default) against the first-order H = slab thickness / |grad g|.
* ``pitch-width``: contours fitted to a band printed as wide as its local pitch (the default,
  session 11) against the profile's W(H) whatever the pitch.
* ``cavity``: one print measured with designed cavities as surface (the default) and with them
  filled like pores (``scipy.ndimage.binary_fill_holes``, before session 10).

Prints per variant the width error, the volume error, the print metrics and the time.

    .venv/bin/python bench/bench_print_ablation.py DIR --compare deformation [--voxel 0.25]

(``pitch-width`` also prints the width error against W(H), the ``width_error_nominal`` of the
report, since the default's is against the width printed.)
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from scipy import ndimage

import sim.metrics as metrics
from core.stages import Field, Layers, TetMesh, Toolpath
from sim.deposition import DepositionConfig, covering_grid, deposit
from slicer.config import JobConfig, load_job
from slicer.extrusion import load_profile
from slicer.layers import extract_layers, iso_surfaces
from slicer.operators import build_operators
from slicer.toolpath.build import compute_toolpath
from slicer.toolpath.flush import flush_toolpath


def _toolpath(layers: Layers, job: JobConfig, tet: TetMesh) -> tuple[Toolpath, dict[str, Any]]:
    profile = load_profile(job.extrusion.profile)
    result = compute_toolpath(layers, job, profile)
    toolpath, _ = flush_toolpath(result.toolpath, tet, profile)
    return toolpath, result.report


def _print(toolpath: Toolpath, mesh: trimesh.Trimesh, job: JobConfig, voxel: float,
           fill: Callable[..., np.ndarray] | None = None) -> str:
    profile = load_profile(job.extrusion.profile)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    config = DepositionConfig(voxel_mm=voxel)
    grid = covering_grid(toolpath, profile, np.stack([v.min(0), v.max(0)]), config)
    dep = deposit(toolpath, profile, config, grid=grid)
    original = metrics.fill_enclosed
    if fill is not None:
        metrics.fill_enclosed = fill  # type: ignore[assignment]
    try:
        q = metrics.inspect_deposit(dep, v, f, toolpath)
    finally:
        metrics.fill_enclosed = original
    s = q.surface.stats()
    return (f"infill {100 * q.infill_ratio:.2f} %, interior {100 * q.interior_infill_ratio:.2f} %, "
            f"pores {100 * q.pore_ratio:.3f} %, over {100 * q.over_deposition:.2f} %, surface "
            f"error mean {s['mean']:.3f} / p95 {s['p95']:.3f} / max {s['max']:.2f} mm")


def _summary(report: dict[str, Any], model_mm3: float) -> str:
    width = ", ".join(f"{k} p50/p90 {100 * v['p50']:.1f}/{100 * v['p90']:.1f} %"
                      for k, v in report["width_error"].items())
    nominal = ", ".join(f"{k} p90 {100 * v['p90']:.1f} %"
                        for k, v in report.get("width_error_nominal", {}).items())
    volume = float(report["deposited_volume_mm3"]) / model_mm3 - 1.0
    return f"width {width} (against W(H): {nominal}); volume {100 * volume:+.2f} %"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("job", type=Path, help="a directory written by mesp slice")
    ap.add_argument("--compare", choices=["deformation", "slab-heights", "pitch-width", "cavity"],
                    required=True)
    ap.add_argument("--voxel", type=float, default=0.25, help="deposition voxel, mm")
    args = ap.parse_args()
    job = load_job(args.job / "job.toml")
    # the job file written by mesp slice holds the settings of its day: today's defaults here
    job = job.with_overrides(toolpath={"deformation_iterations": 200,
                                       "deformation_tolerance": 0.01})
    tet, field = TetMesh.load(args.job), Field.load(args.job)
    mesh = trimesh.load(args.job / "model.ply", force="mesh", process=False)
    model_mm3 = abs(float(mesh.volume))
    matched = extract_layers(tet, field).layers
    variants: list[tuple[str, Layers, JobConfig, Callable[..., np.ndarray] | None]]
    if args.compare == "deformation":
        old = job.with_overrides(toolpath={"deformation_iterations": 6,
                                           "deformation_tolerance": 0.0})
        variants = [("to tolerance", matched, job, None), ("6 iterations", matched, old, None)]
    elif args.compare == "slab-heights":
        first = iso_surfaces(build_operators(tet), field)
        variants = [("slab-matched H", matched, job, None), ("first-order H", first, job, None)]
    elif args.compare == "pitch-width":
        fixed = job.with_overrides(toolpath={"pitch_width": False})
        variants = [("pitch width", matched, job, None), ("W(H)", matched, fixed, None)]
    else:
        def filled(mask: np.ndarray, seeds: np.ndarray | None = None) -> np.ndarray:
            return np.asarray(ndimage.binary_fill_holes(mask))

        variants = [("cavity as surface", matched, job, None),
                    ("cavity filled", matched, job, filled)]
    built: tuple[Layers, JobConfig, Toolpath, dict[str, Any]] | None = None
    for name, layers, cfg, fill in variants:
        t0 = time.perf_counter()
        if built is None or built[0] is not layers or built[1] is not cfg:
            built = (layers, cfg, *_toolpath(layers, cfg, tet))  # the cavity pair shares one
        toolpath, report = built[2], built[3]
        t1 = time.perf_counter()
        printed = _print(toolpath, mesh, cfg, args.voxel, fill)
        t2 = time.perf_counter()
        print(f"{name}: {_summary(report, model_mm3)}; {printed} "
              f"(toolpath {t1 - t0:.1f} s, print {t2 - t1:.1f} s)", flush=True)


if __name__ == "__main__":
    main()
