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

and one layer as a picture (its lines, and the coverage samples left bare or covered twice):

    PYTHONPATH=OLD_TREE python bench/thin_walls.py --dump JOBDIR LAYER before.npz
    PYTHONPATH=.        python bench/thin_walls.py --dump JOBDIR LAYER after.npz
    python bench/thin_walls.py --figure before.npz after.npz OUT.png
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
    # ink laid beyond what too-thin components hold (before the slab correction the
    # pipeline applies: an upper bound of the report's toolpath.too_thin)
    row["too_thin_share"] = (result.thin.excess_mm3 / model_volume
                             if result.thin is not None else 0.0)
    return row


def dump(job_dir: Path, index: int, out: Path) -> None:
    """Layer ``index``'s waypoints, boundary and coverage samples (with their pass counts)
    as printed by the code on PYTHONPATH, into ``out`` (npz)."""
    import numpy as np

    from core.stages import Layers
    from slicer.config import load_job
    from slicer.extrusion import load_profile
    from slicer.toolpath.coverage import (
        SAME_PASS,
        _covered_pairs,
        _passes,
        _sample_layer,
        _segments,
    )
    from slicer.toolpath.layer_build import layer_pattern, layer_toolpath, split_layers
    from slicer.toolpath.linking import deposit_mask
    from slicer.toolpath.surface import boundary_edges

    job = load_job(job_dir / "job.toml")
    layer = split_layers(Layers.load(job_dir))[index]
    res = layer_toolpath(layer, layer_pattern(index, job.toolpath.first_pattern), job.toolpath,
                         load_profile(job.extrusion.profile), False)
    wp = res.waypoints
    seg = _segments(wp, np.arange(len(wp.position)))  # type: ignore[arg-type]
    points, normal = _sample_layer(layer.vertices, layer.faces.astype(np.int64), 8000,
                                   np.random.default_rng(0))
    i, j = _covered_pairs(points, normal, seg)
    passes = _passes(len(points), i, j, seg, SAME_PASS * 2.0 * float(np.median(seg.half_width)))
    err = [c.width_error for c in res.components]
    np.savez(out, position=wp.position, deposit=deposit_mask(wp.extrude, wp.path),
             boundary=layer.vertices[boundary_edges(layer.faces)], samples=points,
             passes=passes, width_error=np.concatenate(err) if err else np.zeros(0))


def figure(before: Path, after: Path, out: Path) -> None:
    """Two dumps of one layer side by side: lines (extruding green, travel dotted), samples
    left bare (red) and covered twice (blue), in the layer's two widest axes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.collections import LineCollection

    data = [np.load(p) for p in (before, after)]
    axes_xyz = np.argsort(np.ptp(data[0]["samples"], axis=0))[::-1][:2]
    fig, axes = plt.subplots(1, 2, figsize=(16, 6.5))
    for ax, d, name in zip(axes, data, ("before", "after"), strict=True):
        b = d["boundary"][:, :, axes_xyz]
        ax.add_collection(LineCollection(b, colors="k", lw=0.6))
        pos = d["position"][:, axes_xyz]
        seg = np.stack([pos[:-1], pos[1:]], axis=1)
        ax.add_collection(LineCollection(seg[d["deposit"]], colors="green", lw=1.2))
        ax.add_collection(LineCollection(seg[~d["deposit"]], colors="orange", lw=0.4,
                                         linestyles="dotted"))
        s, n = d["samples"][:, axes_xyz], d["passes"]
        ax.scatter(*s[n == 0].T, s=2, c="red", label="bare")
        ax.scatter(*s[n >= 2].T, s=2, c="blue", label="covered twice")
        err = d["width_error"]
        p90 = f"{100 * np.percentile(err, 90):.0f} %" if len(err) else "/"
        ax.set_title(f"{name}: bare {100 * np.mean(n == 0):.1f} %, twice "
                     f"{100 * np.mean(n >= 2):.1f} %, width error p90 {p90}")
        ax.set_aspect("equal")
        ax.autoscale()
        ax.set_xlabel("mm")
    axes[0].legend(loc="upper right", markerscale=4)
    fig.tight_layout()
    fig.savefig(out, dpi=80)


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
    ap.add_argument("--dump", nargs=3, metavar=("JOBDIR", "LAYER", "OUT"),
                    help="write one layer's lines and coverage samples (npz)")
    ap.add_argument("--figure", nargs=3, type=Path, metavar=("BEFORE", "AFTER", "OUT"),
                    help="draw two --dump files side by side (PNG)")
    args = ap.parse_args()
    if args.dump:
        dump(Path(args.dump[0]), int(args.dump[1]), Path(args.dump[2]))
        return
    if args.figure:
        figure(*args.figure)
        return
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
