"""Slicing benchmark on the bundled examples at the paper's sizes (Table 1).

Each example runs `mesp slice` in its own process (so peak memory is per example) and the
stage timings are read back from its report.json. Usage:

    .venv/bin/python bench/run.py [--examples socket aorta ...] [--until layers|toolpath]
                                  [--repeat N] [--out bench/results] [--cache DIR]
                                  [--edge-length MM] [--layer-height MM] [--no-baselines]

Prints one row per example: tets, layers, stage timings (median over repeats), peak memory,
and under it the toolpath quality of the last run (width error per pattern, volume error,
extrusion starts per layer component, overall and per pattern, connector volume fraction).
With --cache DIR the tet mesh of each example is made once (timed, in DIR/<name>.vtu) and
the repeats slice that mesh, so fTetWild's minutes are not paid per repeat; its time is in
the first run's `tetrahedralize` column.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"

# Paper Table 1: tets, curved slicing s, toolpath s (C++/MKL on a desktop).
PAPER = {
    "socket": (255_800, 57.2, 198.5),
    "actuator": (207_300, 37.2, 29.6),
    "aorta": (115_500, 15.1, 20.8),
    "membrane": (197_500, 11.9, 64.2),
}


def run_one(
    name: str, until: str, out: Path, edge: float | None, model: Path | None = None,
    layer_height: float | None = None, baselines: bool = True,
) -> dict[str, Any]:
    """Slice one example in a child process; returns its report plus peak memory (MB)."""
    model = model or next(EXAMPLES.glob(f"{name}.*[lLyY]"))
    job = EXAMPLES / f"{name}.toml"
    cmd = [sys.executable, "-m", "mesp_cell.cli", "slice", str(model), "--out", str(out)]
    cmd += ["--until", until, "--quiet"]
    if job.is_file():
        cmd += ["--job", str(job)]
    if edge is not None:
        cmd += ["--edge-length", str(edge)]
    if layer_height is not None:
        cmd += ["--layer-height", str(layer_height)]
    if not baselines:
        cmd += ["--no-baselines"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    start = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(f"{name}: mesp slice failed:\n{proc.stderr}")
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    report = json.loads((out / "report.json").read_text())
    report["bench"] = {"wall_s": wall, "peak_mb": max(peak, before) / 1024.0}
    return report


def _to_vtu(job_dir: Path, path: Path) -> None:
    """Cache a job's tet mesh as .vtu (a format `mesp slice` reads)."""
    sys.path.insert(0, str(ROOT))
    from core.stages import TetMesh
    from slicer.mesh_io import write_tet_mesh

    path.parent.mkdir(parents=True, exist_ok=True)
    write_tet_mesh(TetMesh.load(job_dir), path)


def _quality(tp: dict[str, Any]) -> str:
    """One line of toolpath quality: width error per pattern, volume error, starts."""
    we = tp["width_error"]
    parts = [f"{pat} width err p50/p90 {we[pat]['p50']:.3f}/{we[pat]['p90']:.3f}"
             for pat in ("contour", "stripe")]
    nominal = tp.get("width_error_nominal", {}).get("contour")
    if nominal:  # against the profile's W(H), not the width printed (differs when flow-fitted)
        parts.append(f"contour vs W(H) p90 {nominal['p90']:.3f}")
    vol = tp.get("volume_error")
    parts.append(f"volume err {vol:+.4f}" if isinstance(vol, float) else "volume err -")
    st = tp.get("extrusion_starts", {})
    if isinstance(st, dict) and "mean_per_component" in st:
        parts.append(f"starts/component mean {st['mean_per_component']:.2f} median "
                     f"{st.get('median_per_component', float('nan')):.1f} max "
                     f"{st['max_per_component']}")
    for pat in ("contour", "stripe"):  # per pattern, from the per-layer statistics
        per = [s for row in tp.get("per_layer", []) if row.get("pattern") == pat
               for s in row.get("extrusion_starts", [])]
        if per:
            parts.append(f"{pat} starts mean {statistics.mean(per):.2f} median "
                         f"{statistics.median(per):.1f} max {max(per)}")
    if "connector_volume_fraction" in tp:
        parts.append(f"connector volume {tp['connector_volume_fraction']:.3f}")
    return "; ".join(parts)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", nargs="+", default=list(PAPER))
    parser.add_argument("--until", default="toolpath", choices=["tetmesh", "layers", "toolpath"])
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--edge-length", type=float, default=None)
    parser.add_argument("--layer-height", type=float, default=None,
                        help="override the job's layer height, mm (e.g. to reach a layer count)")
    parser.add_argument("--no-baselines", action="store_true",
                        help="mesp slice --no-baselines (production settings)")
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    parser.add_argument("--cache", type=Path, default=None, help="tet mesh cache directory")
    args = parser.parse_args()

    stages = ["load", "tetrahedralize", "slicing", "toolpath", "total"]
    header = f"{'model':<10}{'tets':>9}{'layers':>8}" + "".join(f"{s:>15}" for s in stages)
    print(header + f"{'peak MB':>10}{'paper slicing/toolpath s':>26}")
    for name in args.examples:
        runs: list[dict[str, Any]] = []
        model = None
        if args.cache is not None:
            model = args.cache / f"{name}.vtu"
            if not model.is_file():
                first = run_one(name, "tetmesh", args.out / name, args.edge_length)
                _to_vtu(args.out / name, model)
                runs.append(first)
        for _ in range(args.repeat):
            report = run_one(name, args.until, args.out / name, args.edge_length, model,
                             args.layer_height, not args.no_baselines)
            if runs and "tetrahedralize" in runs[0]["timing_s"]:
                report["timing_s"]["tetrahedralize"] = runs[0]["timing_s"]["tetrahedralize"]
            runs.append(report)
        runs = [r for r in runs if "slicing" in r or args.until == "tetmesh"]
        last = runs[-1]
        timing = {
            s: statistics.median(float(r["timing_s"].get(s, float("nan"))) for r in runs)
            for s in stages
        }
        peak = max(float(r["bench"]["peak_mb"]) for r in runs)
        paper = PAPER.get(name)
        paper_txt = f"{paper[1]:.1f} / {paper[2]:.1f}" if paper else "-"
        print(
            f"{name:<10}{last['mesh']['tets']:>9}{last.get('slicing', {}).get('layers', '-'):>8}"
            + "".join(f"{timing[s]:>15.2f}" for s in stages)
            + f"{peak:>10.0f}{paper_txt:>26}"
        )
        tp = last.get("toolpath")
        if isinstance(tp, dict) and "width_error" in tp:
            print("  " + _quality(tp))
        (args.out / f"{name}.json").write_text(json.dumps(runs, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
