"""Coverage of contour layers with eq. 9's lines (before) and fitted to the local width.

Every STEP-th contour layer of each sliced job (``mesp slice MODEL --until layers`` is
enough) is printed twice on the same layers, ``toolpath.fit_ridge`` false and true, and
measured as ``mesp slice`` measures it: area-weighted gap and overlap (``toolpath.coverage``,
connectors and blends included), the contour width error p50/p90 and the chosen layers'
volume error (deposited / integral of H - 1). Usage:

    .venv/bin/python bench/contour_coverage.py JOBDIR ... [--step 2] [--out FILE.json]
        [--figure LAYER --png FILE.png]

``--figure LAYER`` draws that layer of the first job both ways: the coverage samples
coloured bare (red) / once (grey) / covered twice (blue) under the extruding path.
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

from core.stages import Layers, Pattern
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

MODES = (("eq9", False), ("ridge-fit", True))  # toolpath.fit_ridge


def contour_layers(layers: Layers, first: str, step: int) -> Layers:
    """The layers of ``layers`` printed as contours, every ``step``-th of them."""
    ids = np.arange(int(layers.face_layer.max()) + 1)
    contour = ids[[layer_pattern(int(i), first) == Pattern.CONTOUR for i in ids]][::step]
    chosen = np.isin(layers.face_layer, contour)
    return Layers(layers.vertices, layers.faces[chosen], layers.face_layer[chosen],
                  layers.vertex_height, layers.vertex_direction)


def measure(job_dir: Path, step: int, fit: bool) -> dict[str, Any]:
    """Contour coverage, width error and volume error of the chosen layers."""
    job = load_job(job_dir / "job.toml")
    cfg = job.with_overrides(toolpath={"fit_ridge": fit}).toolpath
    profile = load_profile(job.extrusion.profile)
    sub = contour_layers(Layers.load(job_dir), cfg.first_pattern, step)
    start = time.perf_counter()
    results = [layer_toolpath(m, layer_pattern(m.index, cfg.first_pattern), cfg, profile, False)
               for m in split_layers(sub) if len(m.faces)]
    toolpath, _ = assemble(results)
    cov = layer_coverage(sub, toolpath)
    comps = [c for r in results for c in r.components if c.pattern == Pattern.CONTOUR]
    err = np.concatenate([c.width_error for c in comps]) if comps else np.zeros(0)
    sel = (cov.pattern == Pattern.CONTOUR) & (cov.area > 0)
    required = sum(c.required_mm3 for c in comps)
    return {
        "layers": int(sel.sum()),
        "gap": float(np.average(cov.gap[sel], weights=cov.area[sel])) if sel.any() else None,
        "overlap": (float(np.average(cov.overlap[sel], weights=cov.area[sel]))
                    if sel.any() else None),
        "width_p50": float(np.percentile(err, 50)) if len(err) else None,
        "width_p90": float(np.percentile(err, 90)) if len(err) else None,
        "volume_error": (sum(c.deposited_mm3 for c in comps) / required - 1.0
                         if required else None),
        "starts": int(sum(c.extrusion_starts for c in comps)),
        "seconds": time.perf_counter() - start,
    }


def figure(job_dir: Path, layer: int, png: Path) -> None:
    """One layer's coverage with eq. 9's lines and fitted to the local width, side by side."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    job = load_job(job_dir / "job.toml")
    profile = load_profile(job.extrusion.profile)
    layers = Layers.load(job_dir)
    mesh = split_layers(layers)[layer]
    tri = mesh.vertices[mesh.faces]
    area = 0.5 * float(np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]),
                                      axis=1).sum())
    # the layer's best-fit plane as the drawing plane
    centre = mesh.vertices.mean(axis=0)
    axes = np.linalg.svd(mesh.vertices - centre, full_matrices=False)[2][:2]
    fig, panels = plt.subplots(1, 2, figsize=(12, 6))
    for ax, (name, fit) in zip(panels, MODES, strict=True):
        cfg = job.with_overrides(toolpath={"fit_ridge": fit}).toolpath
        res = layer_toolpath(mesh, layer_pattern(mesh.index, cfg.first_pattern), cfg, profile,
                             False)
        tp, _ = assemble([res])
        seg = _segments(tp, np.arange(len(tp.path)))
        w = 2.0 * float(np.median(seg.half_width))
        count = int(min(4 * SAMPLES_PER_W2 * area / w**2, 40_000))
        points, normal = _sample_layer(mesh.vertices, mesh.faces.astype(np.int64), count,
                                       np.random.default_rng(1))
        i, j = _covered_pairs(points, normal, seg)
        passes = _passes(count, i, j, seg, 2.0 * w)
        xy = (points - centre) @ axes.T
        colour = np.where(passes == 0, "red", np.where(passes == 1, "0.85", "tab:blue"))
        ax.scatter(xy[:, 0], xy[:, 1], c=colour, s=2, linewidths=0)
        path = (np.asarray(tp.position) - centre) @ axes.T
        ext = np.asarray(tp.extrude)
        ax.plot(np.where(ext, path[:, 0], np.nan), np.where(ext, path[:, 1], np.nan), "k-",
                lw=0.6)
        ax.set_title(f"{job_dir.name} layer {layer}, {name}: bare {100 * np.mean(passes == 0):.1f}"
                     f" %, twice {100 * np.mean(passes >= 2):.1f} %")
        ax.set_aspect("equal")
        ax.set_xlabel("mm")
    fig.tight_layout()
    fig.savefig(png, dpi=80)


def _pct(x: float | None) -> str:
    return "/" if x is None else f"{100.0 * x:.1f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("jobs", nargs="+", type=Path, help="sliced job directories")
    ap.add_argument("--step", type=int, default=2, help="every STEP-th contour layer")
    ap.add_argument("--out", type=Path, help="write every number as JSON")
    ap.add_argument("--figure", type=int, help="draw this layer of the first job instead")
    ap.add_argument("--png", type=Path, default=Path("contour_coverage.png"))
    args = ap.parse_args()
    if args.figure is not None:
        figure(args.jobs[0], args.figure, args.png)
        return
    out: dict[str, Any] = {}
    for job_dir in args.jobs:
        for name, fit in MODES:
            row = measure(job_dir, args.step, fit)
            out[f"{job_dir.name}:{name}"] = row
            print(f"{job_dir.name}:{name:10s} layers {row['layers']:3d}  gap/overlap "
                  f"{_pct(row['gap'])}/{_pct(row['overlap'])}  width p50/p90 "
                  f"{_pct(row['width_p50'])}/{_pct(row['width_p90'])}  volume "
                  f"{_pct(row['volume_error'])}  starts {row['starts']}  "
                  f"({row['seconds']:.0f} s)", flush=True)
            if args.out:
                args.out.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
