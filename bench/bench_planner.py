"""Benchmark of `mesp plan`: waypoints/s, TCP speed fidelity, stage timings, peak memory.

    .venv/bin/python bench/bench_planner.py                 # synthetic 120k-waypoint job
    .venv/bin/python bench/bench_planner.py --n 500000      # a bigger synthetic job
    .venv/bin/python bench/bench_planner.py --shape dome    # curved normals (up to ~15 deg)
    .venv/bin/python bench/bench_planner.py DIR/toolpath.npz  # a real toolpath
    .venv/bin/python bench/bench_planner.py --toolpath out/socket --toolpath out/hemi  # examples

Prints one JSON object per job (``--toolpath`` jobs: one line each, then a Markdown table).
Each plan is also put through the robot streamer's own checks before motion
(``StreamPlan.load``: joint speeds, the nozzle's bow off a depositing step), as the cell would.
``speed_within_5pct`` is the fraction of extruding waypoints whose TCP speed on the following
step lies within 5 % of the toolpath speed (target: >= 0.99); repeated waypoints (zero-length
steps) have no speed and are left out.
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from core.errors import InputError
from core.stages import Toolpath
from mesp_cell.drivers.stream import StreamPlan
from planner.cell import load_cell
from planner.plan import plan
from tests.planner import synthetic

STREAM_DT_S = 0.002  # the UR5e servo period the streamer resamples at


def speed_fidelity(result) -> float:  # type: ignore[no-untyped-def]
    """Fraction of extruding waypoints with TCP speed within 5 % of the toolpath speed."""
    tr = result.trajectory
    step = np.linalg.norm(np.diff(tr.tcp, axis=0), axis=1)
    v = step / np.diff(tr.t)
    # the toolpath speed varies linearly along a segment: a step's target is its ends' mean
    target = 0.5 * (result.samples.speed[:-1] + result.samples.speed[1:])
    pick = (tr.waypoint[:-1] >= 0) & tr.extrude[:-1] & (step > 1e-6)
    return float(np.mean(np.abs(v[pick] / target[pick] - 1.0) <= 0.05)) if pick.any() else 1.0


def streamer_verdict(result) -> str:  # type: ignore[no-untyped-def]
    """"accepts", or the streamer's one-line refusal of the planned trajectory."""
    with tempfile.TemporaryDirectory() as tmp:
        path = result.trajectory.save(Path(tmp))
        try:
            StreamPlan.load(path, STREAM_DT_S)
        except InputError as e:
            return f"refuses: {e}"
    return "accepts"


def run_one(tp: Toolpath, cell, source: str) -> dict:  # type: ignore[no-untyped-def]
    """Plan ``tp`` once and collect the benchmark numbers."""
    wall, cpu = time.perf_counter(), time.process_time()
    result = plan(tp, cell)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    rep = result.report
    peak = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1)
    return {
        "source": source,
        "waypoints": len(tp),
        "samples": len(result.trajectory),
        "wall_s": round(wall, 3),
        "cpu_s": round(cpu, 3),
        "waypoints_per_s_wall": round(len(tp) / wall),
        "waypoints_per_s_cpu": round(len(tp) / cpu),
        "speed_within_5pct": speed_fidelity(result),
        "stage_s": rep["timing_s"],
        "peak_rss_mb": peak,
        "status": rep["status"],
        "min_clearance_mm": rep["min_clearance_mm"],
        "min_clearance_pair": rep["min_clearance_pair"],
        "alpha_deg": [round(rep["alpha_deg"]["min"], 1), round(rep["alpha_deg"]["max"], 1)]
        if "min" in rep["alpha_deg"] else None,
        "lean_deg": [round(rep["lean_deg"]["min"], 1), round(rep["lean_deg"]["max"], 1)]
        if "min" in rep["lean_deg"] else None,
        "tilted_samples": rep["alpha_deg"]["tilted_samples"],
        "leaned_samples": rep["lean_deg"]["leaned_samples"],
        "unreachable": rep["unreachable"]["count"],
        "unreachable_by_reason": rep["unreachable"]["by_reason"],
        "unreachable_between_waypoints": rep["unreachable"]["between_waypoints"],
        "normals_repaired": rep["normals_repaired"],
        "gel_fill_mm": rep["gel_fill_mm"],
        "placement": rep["placement"],
        "over_deposition": rep["over_deposition"],
        "duration_s": rep["duration_s"],
        "upright": rep["upright"],
        "continuity": rep["continuity"],
        "streamer": streamer_verdict(result),
    }


def table(rows: list[dict]) -> str:
    """The per-example Markdown table."""
    head = ("| job | status | waypoints | plan s | wp/s | duration h | speed within 5% | "
            "over-deposition | min clearance mm | alpha deg | lean deg | uprighted (max deg) | "
            "singularity margin | inserted (steps) | unreachable (reasons) | streamer |")
    out = [head, "|" + " --- |" * 16]
    for r in rows:
        reasons = ", ".join(f"{k}: {v}" for k, v in r["unreachable_by_reason"].items())
        up, cont = r["upright"], r["continuity"]
        out.append(
            f"| {Path(r['source']).name} | {r['status']} | {r['waypoints']} | "
            f"{r['wall_s']:.1f} | {r['waypoints_per_s_wall']} | {r['duration_s'] / 3600:.2f} | "
            f"{100 * r['speed_within_5pct']:.2f}% | "
            f"{100 * r['over_deposition']['fraction']:.3f}% | {r['min_clearance_mm']:.1f} | "
            f"{r['alpha_deg']} | {r['lean_deg']} | {up['samples']} ({up['max_deg']:g}) | "
            f"{up['margin_min']:.3f} | {cont['samples_inserted']} ({cont['steps_split']}) | "
            f"{r['unreachable']}" + (f" ({reasons})" if reasons else "")
            + f" | {r['streamer']} |")
    return "\n".join(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("toolpath", nargs="?", type=Path, help="a toolpath.npz (or its job dir)")
    ap.add_argument("--toolpath", dest="jobs", action="append", type=Path, default=[],
                    metavar="DIR", help="a sliced job (dir or toolpath.npz); repeatable")
    ap.add_argument("--n", type=int, default=120_000, help="synthetic waypoints (default 120k)")
    ap.add_argument("--cell", type=Path, help="cell TOML")
    ap.add_argument("--shape", choices=["spiral", "dome"], default="spiral",
                    help="synthetic job: stacked spiral (flat layers) or curved dome patch")
    args = ap.parse_args()
    cell = load_cell(args.cell)
    jobs = list(args.jobs) + ([args.toolpath] if args.toolpath is not None else [])
    if jobs:
        rows = []
        for job in jobs:
            d = job if job.is_dir() else job.parent
            rows.append(run_one(Toolpath.load(d), cell, str(d)))
            print(json.dumps(rows[-1]), flush=True)
        if len(rows) > 1:
            print(table(rows))
        return 0
    if args.shape == "dome":
        tp = synthetic.big_dome(args.n)
        source = f"synthetic curved dome patch, {len(tp)} waypoints"
    else:
        tp = synthetic.big(args.n)
        source = f"synthetic stacked spiral, {len(tp)} waypoints"
    print(json.dumps(run_one(tp, cell, source), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
