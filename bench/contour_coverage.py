"""Coverage of contour layers with the rings joined by connectors (before) and as a spiral.

Every STEP-th contour layer of each sliced job (``mesp slice MODEL --until layers`` is
enough) is printed twice on the same layers, ``toolpath.spiral_rings`` false and true, and
measured as ``mesp slice`` measures it: area-weighted gap and overlap (``toolpath.coverage``,
connectors and blends included), the contour width error p50/p90 and the chosen layers'
volume error (deposited / integral of H - 1). Usage:

    .venv/bin/python bench/contour_coverage.py JOBDIR ... [--step 2] [--out FILE.json]
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
from slicer.toolpath.coverage import layer_coverage
from slicer.toolpath.layer_build import layer_pattern, layer_toolpath, split_layers

MODES = (("connectors", False), ("spiral", True))


def contour_layers(layers: Layers, first: str, step: int) -> Layers:
    """The layers of ``layers`` printed as contours, every ``step``-th of them."""
    ids = np.arange(int(layers.face_layer.max()) + 1)
    contour = ids[[layer_pattern(int(i), first) == Pattern.CONTOUR for i in ids]][::step]
    chosen = np.isin(layers.face_layer, contour)
    return Layers(layers.vertices, layers.faces[chosen], layers.face_layer[chosen],
                  layers.vertex_height, layers.vertex_direction)


def measure(job_dir: Path, step: int, spiral: bool) -> dict[str, Any]:
    """Contour coverage, width error and volume error of the chosen layers."""
    job = load_job(job_dir / "job.toml")
    cfg = job.with_overrides(toolpath={"spiral_rings": spiral}).toolpath
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


def _pct(x: float | None) -> str:
    return "/" if x is None else f"{100.0 * x:.1f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("jobs", nargs="+", type=Path, help="sliced job directories")
    ap.add_argument("--step", type=int, default=2, help="every STEP-th contour layer")
    ap.add_argument("--out", type=Path, help="write every number as JSON")
    args = ap.parse_args()
    out: dict[str, Any] = {}
    for job_dir in args.jobs:
        for name, spiral in MODES:
            row = measure(job_dir, args.step, spiral)
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
