"""Benchmark of `mesp plan`: waypoints/s, TCP speed fidelity, stage timings, peak memory.

    .venv/bin/python bench/bench_planner.py                 # synthetic 120k-waypoint job
    .venv/bin/python bench/bench_planner.py --n 500000      # a bigger synthetic job
    .venv/bin/python bench/bench_planner.py --shape dome    # curved normals (up to ~15 deg)
    .venv/bin/python bench/bench_planner.py DIR/toolpath.npz  # a real toolpath

Prints one JSON object. ``speed_within_5pct`` is the fraction of extruding waypoints whose TCP
speed on the following step lies within 5 % of the toolpath speed (target: >= 0.99).
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from planner.cell import load_cell
from planner.plan import plan
from slicer.stages import Toolpath
from tests.planner import synthetic


def speed_fidelity(result) -> float:  # type: ignore[no-untyped-def]
    """Fraction of extruding waypoints with TCP speed within 5 % of the toolpath speed."""
    tr = result.trajectory
    v = np.linalg.norm(np.diff(tr.tcp, axis=0), axis=1) / np.diff(tr.t)
    target = result.samples.speed[:-1]
    pick = (tr.waypoint[:-1] >= 0) & tr.extrude[:-1]
    return float(np.mean(np.abs(v[pick] / target[pick] - 1.0) <= 0.05)) if pick.any() else 1.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("toolpath", nargs="?", type=Path, help="a toolpath.npz (or its job dir)")
    ap.add_argument("--n", type=int, default=120_000, help="synthetic waypoints (default 120k)")
    ap.add_argument("--cell", type=Path, help="cell TOML")
    ap.add_argument("--shape", choices=["spiral", "dome"], default="spiral",
                    help="synthetic job: stacked spiral (flat layers) or curved dome patch")
    args = ap.parse_args()
    cell = load_cell(args.cell)
    if args.toolpath is not None:
        d = args.toolpath if args.toolpath.is_dir() else args.toolpath.parent
        tp = Toolpath.load(d)
        source = str(args.toolpath)
    else:
        if args.shape == "dome":
            tp = synthetic.big_dome(args.n)
            source = f"synthetic curved dome patch, {len(tp)} waypoints"
        else:
            tp = synthetic.big(args.n)
            source = f"synthetic stacked spiral, {len(tp)} waypoints"
    wall, cpu = time.perf_counter(), time.process_time()
    result = plan(tp, cell)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    rep = result.report
    out = {
        "source": source,
        "waypoints": len(tp),
        "samples": len(result.trajectory),
        "wall_s": round(wall, 3),
        "cpu_s": round(cpu, 3),
        "waypoints_per_s_wall": round(len(tp) / wall),
        "waypoints_per_s_cpu": round(len(tp) / cpu),
        "speed_within_5pct": speed_fidelity(result),
        "stage_s": rep["timing_s"],
        "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1),
        "status": rep["status"],
        "min_clearance_mm": rep["min_clearance_mm"],
        "unreachable": rep["unreachable"]["count"],
        "over_deposition": rep["over_deposition"],
        "duration_s": rep["duration_s"],
    }
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
