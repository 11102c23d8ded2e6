"""Thin walls, tips and sharp corners: the toolpath of sliced jobs, measured as ``mesp slice``
measures it.

Every layer of each job (``mesp slice MODEL --scale-to 40 --no-baselines --until layers``
is enough: the toolpath is rebuilt here from layers.npz with the job's settings) is printed
by the code on ``PYTHONPATH`` and measured: contour width error p50 / p90 (the report's
measure), area-weighted gap / overlap per pattern (``toolpath.coverage``, connectors
included), the volume error against the model (deposited / model.volume_mm3 - 1, as the
report's ``volume_error``, before flushing, which keeps the ink) and against the layers'
required volume. Run it once with the code before a change and once after, on the same job
directories (so the same tet meshes and layers), then compare:

    PYTHONPATH=OLD_TREE python bench/thin_walls.py JOBDIR ... --out before.json
    PYTHONPATH=.        python bench/thin_walls.py JOBDIR ... --out after.json
    python bench/thin_walls.py --compare before.json after.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any, cast


def measure(job_dir: Path) -> dict[str, Any]:
    """Width error, coverage and volume error of every layer of ``job_dir``."""
    from core.stages import Layers
    from slicer.config import load_job
    from slicer.extrusion import load_profile
    from slicer.toolpath.build import compute_toolpath
    from slicer.toolpath.coverage import layer_coverage

    job = load_job(job_dir / "job.toml")
    profile = load_profile(job.extrusion.profile)
    layers = Layers.load(job_dir)
    model_volume = float(json.loads((job_dir / "report.json").read_text())["model"]["volume_mm3"])
    start = time.perf_counter()
    result = compute_toolpath(layers, job, profile, measure_baselines=False, workers=1)
    seconds = time.perf_counter() - start
    coverage = layer_coverage(layers, result.toolpath).summary()
    rep = result.report
    row: dict[str, Any] = {"layers": int(layers.layer_count), "seconds": seconds}
    for name in ("contour", "stripe"):
        cov = cast(dict[str, Any], coverage[name])
        w = rep["width_error"][name]
        row[name] = {"gap": cov["gap"], "overlap": cov["overlap"], "layers": cov["layers"],
                     "width_p50": None if w["n"] == 0 else w["p50"],
                     "width_p90": None if w["n"] == 0 else w["p90"]}
    deposited = float(rep["deposited_volume_mm3"])
    row["volume_error"] = deposited / model_volume - 1.0
    row["layer_volume_error"] = float(rep["layer_volume_error"])
    row["fallbacks"] = {k: int(v) for k, v in rep["thin_fallback"].items()}
    return row


def _pct(x: float | None) -> str:
    return "/" if x is None else f"{100.0 * x:.1f}"


def line(name: str, row: dict[str, Any]) -> str:
    """One printed row: contour width p50/p90, gap/overlap per pattern, volume errors."""
    c, s = row["contour"], row["stripe"]
    return (f"{name:18s} contour p50/p90 {_pct(c['width_p50'])}/{_pct(c['width_p90'])}  "
            f"gap/overlap contour {_pct(c['gap'])}/{_pct(c['overlap'])} stripe "
            f"{_pct(s['gap'])}/{_pct(s['overlap'])}  volume {_pct(row['volume_error'])} "
            f"(layers {_pct(row['layer_volume_error'])})  {row['seconds']:.0f} s")


def compare(before: dict[str, Any], after: dict[str, Any]) -> None:
    """A markdown table of the models both runs measured."""
    print("| model | contour width p50/p90 % | gap/overlap contour % | gap/overlap stripe % "
          "| volume % (model) | volume % (layers) |")
    print("|---|---|---|---|---|---|")
    for name in before:
        if name not in after:
            continue
        b, a = before[name], after[name]

        def pair(key: str, sub: str | None = None, b: Any = b, a: Any = a) -> str:
            x = b[key] if sub is None else b[key][sub]
            y = a[key] if sub is None else a[key][sub]
            return f"{_pct(x)} -> {_pct(y)}"

        print(f"| {name} | {pair('contour', 'width_p50')} / {pair('contour', 'width_p90')} | "
              f"{pair('contour', 'gap')} / {pair('contour', 'overlap')} | "
              f"{pair('stripe', 'gap')} / {pair('stripe', 'overlap')} | "
              f"{pair('volume_error')} | {pair('layer_volume_error')} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("jobs", nargs="*", type=Path, help="sliced job directories")
    ap.add_argument("--out", type=Path, help="write every number as JSON")
    ap.add_argument("--compare", nargs=2, type=Path, metavar=("BEFORE", "AFTER"),
                    help="print a before/after table of two --out files")
    args = ap.parse_args()
    if args.compare:
        compare(*(json.loads(p.read_text()) for p in args.compare))
        return
    out: dict[str, Any] = {}
    for job_dir in args.jobs:
        row = measure(job_dir)
        out[job_dir.name] = row
        print(line(job_dir.name, row), flush=True)
        if args.out:
            args.out.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
