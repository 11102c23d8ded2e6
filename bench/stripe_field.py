"""Coverage of sliced jobs with the stripe field across the contours and parallel.

Every STEP-th layer of each job (the same layers: ``mesp slice MODEL --until layers`` is
enough) is printed again with ``toolpath.stripe_field`` 'across' (the default) and
'parallel', and measured as ``mesp slice`` measures it: area-weighted gap and overlap per
pattern (``toolpath.coverage``), the width error p90 per pattern and the chosen layers'
volume error (deposited / integral of H - 1). Usage:

    .venv/bin/python bench/stripe_field.py JOBDIR ... [--step 3] [--fields across]
        [--out FILE.json]

(run it with PYTHONPATH at another tree to measure that tree's stripes on the same layers).
``--figure LAYER --png FILE`` draws that layer of the first job instead: the coverage
samples bare (red), once (grey), twice (blue) under the extruding path (connectors magenta).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from core.stages import Layers
from slicer.config import load_job
from slicer.extrusion import load_profile
from slicer.toolpath.build import assemble
from slicer.toolpath.coverage import (
    SAMPLES_PER_W2,
    _covered_pairs,
    _passes,
    _sample_layer,
    _segments,
    layer_coverage,
)
from slicer.toolpath.layer_build import layer_pattern, layer_toolpath, split_layers

FIELDS = ("across", "parallel")


def measure(job_dir: Path, step: int, field: str) -> dict[str, Any]:
    """Coverage, width p90 and volume error of every ``step``-th layer with ``field``."""
    job = load_job(job_dir / "job.toml")
    cfg = job.with_overrides(toolpath={"stripe_field": field}).toolpath
    profile = load_profile(job.extrusion.profile)
    layers = Layers.load(job_dir)
    chosen = np.isin(layers.face_layer, np.arange(0, int(layers.face_layer.max()) + 1, step))
    sub = Layers(layers.vertices, layers.faces[chosen], layers.face_layer[chosen],
                 layers.vertex_height, layers.vertex_direction)
    start = time.perf_counter()
    results = [layer_toolpath(m, layer_pattern(m.index, cfg.first_pattern), cfg, profile, False)
               for m in split_layers(sub) if len(m.faces)]
    toolpath, _ = assemble(results)
    coverage = layer_coverage(sub, toolpath).summary()
    comps = [c for r in results for c in r.components]
    row: dict[str, Any] = {"layers": len(results)}
    for code, name in ((0, "contour"), (1, "stripe")):
        err = [c.width_error for c in comps if c.pattern == code]
        flat = np.concatenate(err) if err else np.zeros(0)
        cov: dict[str, Any] = coverage[name]  # type: ignore[assignment]
        row[name] = {"gap": cov["gap"], "overlap": cov["overlap"],
                     "width_p90": float(np.percentile(flat, 90)) if len(flat) else None}
    row["stripe_starts"] = sum(c.extrusion_starts for c in comps if c.pattern == 1)
    required = sum(c.required_mm3 for c in comps)
    row["volume_error"] = sum(c.deposited_mm3 for c in comps) / required - 1.0 if required else None
    row["seconds"] = time.perf_counter() - start
    return row


def figure(job_dir: Path, layer: int, png: Path, title: str) -> None:
    """One layer's coverage under its extruding path, as ``measure`` prints it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    job = load_job(job_dir / "job.toml")
    cfg = job.toolpath
    mesh = split_layers(Layers.load(job_dir))[layer]
    res = layer_toolpath(mesh, layer_pattern(mesh.index, cfg.first_pattern), cfg,
                         load_profile(job.extrusion.profile), False)
    tp, _ = assemble([res])
    seg = _segments(tp, np.arange(len(tp.path)))
    w = 2.0 * float(np.median(seg.half_width))
    tri = mesh.vertices[mesh.faces]
    area = 0.5 * float(np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]),
                                      axis=1).sum())
    count = int(min(16 * SAMPLES_PER_W2 * area / w**2, 60_000))
    points, normal = _sample_layer(mesh.vertices, mesh.faces.astype(np.int64), count,
                                   np.random.default_rng(1))
    i, j = _covered_pairs(points, normal, seg)
    passes = _passes(count, i, j, seg, 2.0 * w)
    # the layer's best-fit plane as the drawing plane
    centre = mesh.vertices.mean(axis=0)
    axes = np.linalg.svd(mesh.vertices - centre, full_matrices=False)[2][:2]
    xy = (points - centre) @ axes.T
    fig, ax = plt.subplots(figsize=(7, 7))
    colour = np.where(passes == 0, "red", np.where(passes == 1, "0.85", "tab:blue"))
    ax.scatter(xy[:, 0], xy[:, 1], c=colour, s=1.5, linewidths=0)
    path = (np.asarray(tp.position) - centre) @ axes.T
    ext = np.asarray(tp.extrude)
    ax.plot(np.where(ext, path[:, 0], np.nan), np.where(ext, path[:, 1], np.nan), "k-", lw=0.6)
    ax.set_title(f"{title}{job_dir.name} layer {layer}: bare {100 * np.mean(passes == 0):.1f} %,"
                 f" twice {100 * np.mean(passes >= 2):.1f} %")
    ax.set_aspect("equal")
    ax.set_xlabel("mm")
    fig.tight_layout()
    fig.savefig(png, dpi=90)


def _pct(x: float | None) -> str:
    return "/" if x is None else f"{100.0 * x:.1f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("jobs", nargs="+", type=Path, help="sliced job directories")
    ap.add_argument("--step", type=int, default=3, help="every STEP-th layer")
    ap.add_argument("--fields", nargs="+", choices=FIELDS, default=list(FIELDS),
                    help="stripe fields to run (default: both)")
    ap.add_argument("--out", type=Path, help="write every number as JSON")
    ap.add_argument("--figure", type=int, help="draw this layer of the first job instead")
    ap.add_argument("--png", type=Path, default=Path("stripe_coverage.png"))
    ap.add_argument("--title", default="", help="prefix of the figure's title")
    args = ap.parse_args()
    if args.figure is not None:
        figure(args.jobs[0], args.figure, args.png, args.title)
        return
    out: dict[str, Any] = {}
    for job_dir in args.jobs:
        for field in args.fields:
            row = measure(job_dir, args.step, field)
            out[f"{job_dir.name}:{field}"] = row
            c, s = row["contour"], row["stripe"]
            print(f"{job_dir.name}:{field:9s} layers {row['layers']:3d}  contour "
                  f"{_pct(c['gap'])}/{_pct(c['overlap'])}  stripe {_pct(s['gap'])}/"
                  f"{_pct(s['overlap'])}  p90 {_pct(c['width_p90'])}/{_pct(s['width_p90'])}  "
                  f"volume {_pct(row['volume_error'])}  stripe starts {row['stripe_starts']}  "
                  f"({row['seconds']:.0f} s)", flush=True)
            if args.out:
                args.out.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
