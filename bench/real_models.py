"""The real-model benchmark: each corpus model through slice, plan and inspect, as a user would.

Each model is scaled to a printable size (``--size``, largest extent, mm) and run with the
default settings through the command line in child processes: ``mesp slice MODEL --scale-to
SIZE --no-baselines --out DIR``, ``mesp plan DIR``, ``mesp inspect DIR``. A step that refuses
keeps its one-line reason (``mesp: error: ...``); the next steps are skipped. An open scan whose
refusal offers ``--repair`` (checked by mesp) is sliced again with it, as a user would. Usage:

    .venv/bin/python bench/real_models.py [--models teapot torus ...] [--size 40]
                                          [--steps slice,plan,inspect] [--voxel 0.4]
                                          [--out bench/results/real_models] [--timeout 900]
                                          [--extra ARG ...]  (more ``mesp slice`` arguments)
                                          [--table]  (only the table again, from OUT)

Writes ``OUT/table.md`` (one row per model, the table the README shows) and ``OUT/results.json``
(every number, per model), and prints the table with stage timings and peak memory.
"""

from __future__ import annotations

import argparse
import fcntl
import json
import math
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.corpus import (
    SHARED_MODELS,
    CorpusModel,
    generated_models,
    shared_models,
)

ROOT = Path(__file__).resolve().parents[1]


def _run(args: list[str], timeout: float) -> tuple[str, str, float, float]:
    """Run ``mesp ARGS``; (status, one-line reason, seconds, peak RSS MB of the child)."""
    cmd = [sys.executable, "-m", "mesp_cell.cli", *args]
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    start = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout,
                              stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return "timeout", f"no answer within {timeout:g} s", time.perf_counter() - start, 0.0
    seconds = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    mem = max(peak, before) / 1024.0
    err = [ln for ln in proc.stderr.splitlines() if ln.startswith("mesp: error:")]
    if proc.returncode == 0:
        return "ok", "", seconds, mem
    if "Traceback" in proc.stderr:
        return "crash", proc.stderr.strip().splitlines()[-1][:200], seconds, mem
    reason = err[-1][len("mesp: error: "):] if err else proc.stderr.strip()[-200:]
    return f"exit {proc.returncode}", reason, seconds, mem


def _get(d: dict[str, Any], *keys: str) -> Any:
    for k in keys:
        if not isinstance(d, dict) or k not in d:
            return None
        d = d[k]
    return d


def _metrics(report: dict[str, Any]) -> dict[str, Any]:
    """The table's numbers from one job's report.json (None where a step did not run)."""
    tp = report.get("toolpath", {})
    plan = report.get("plan", {})
    ins = report.get("inspect", {})
    height = _get(report, "slicing", "height_mm") or {}
    mean = height.get("mean")
    cov = tp.get("coverage", {})
    return {
        "tets": _get(report, "mesh", "tets"),
        "layers": _get(report, "slicing", "layers"),
        "height_cv": (height["std"] / mean) if mean else None,
        "height_max_mm": height.get("max"),
        "height_outside_profile": _get(report, "slicing", "height_outside_profile", "fraction"),
        "gap_contour": _get(cov, "contour", "gap"),
        "overlap_contour": _get(cov, "contour", "overlap"),
        "gap_stripe": _get(cov, "stripe", "gap"),
        "overlap_stripe": _get(cov, "stripe", "overlap"),
        "width_p90_contour": _get(tp, "width_error", "contour", "p90"),
        "width_p90_stripe": _get(tp, "width_error", "stripe", "p90"),
        "volume_error": tp.get("volume_error"),
        "downward_waypoints": _get(tp, "printing_direction", "downward"),
        "plan_status": plan.get("status"),
        # as verified on the executed trajectory: both ends of every depositing step
        "alpha_min": (_get(plan, "verified", "alpha_deg") or [None, None])[0],
        "alpha_max": (_get(plan, "verified", "alpha_deg") or [None, None])[1],
        "verified": _get(plan, "verified", "ok"),
        "min_clearance_mm": _get(plan, "verified", "min_clearance_mm"),
        "speed_within_5pct": _get(plan, "speed_ratio", "within_5pct"),
        "interior_infill": ins.get("interior_infill_ratio"),
        "pores": ins.get("pore_ratio"),
        "surface_error_mm": _get(ins, "surface_error_mm", "mean"),
    }


STEPS = ("slice", "plan", "inspect")


def run_model(model: CorpusModel, out: Path, size: float, timeout: float, extra: list[str],
              steps: tuple[str, ...] = STEPS, voxel: float | None = None,
              previous: dict[str, Any] | None = None) -> dict[str, Any]:
    """Run ``steps`` of slice, plan, inspect on one model; its statuses, reasons, timings and
    metrics. A step not in ``steps`` keeps its result from ``previous`` (this model's row of
    an earlier run into ``out``), so a planner change re-runs plan and inspect on the same
    slices."""
    job = out / model.name
    row: dict[str, Any] = {"model": model.name, "origin": model.origin}
    commands = {
        "slice": ["slice", str(model.path), "--scale-to", str(size), "--no-baselines",
                  "--quiet", "--out", str(job), *extra],
        "plan": ["plan", str(job), "--quiet"],
        "inspect": ["inspect", str(job), "--quiet", "--no-figures",
                    *(["--voxel", str(voxel)] if voxel else [])],
    }
    for name in STEPS:
        if name not in steps:
            if previous is not None and name in previous:
                row[name] = previous[name]
        else:
            status, reason, seconds, mem = _run(commands[name], timeout)
            followed = ""
            if name == "slice" and "re-run with --repair" in reason:
                # as a user would: follow the fix the refusal names (it was checked)
                followed = reason
                status, reason, seconds, mem = _run([*commands[name], "--repair"], timeout)
            row[name] = {"status": status, "reason": reason, "s": round(seconds, 1),
                         "peak_mb": round(mem), "followed_fix": followed}
            print(f"  {model.name:18s} {name:8s} {status:8s} {seconds:7.1f} s  "
                  f"{'(--repair) ' if followed else ''}{reason[:110]}", flush=True)
        done = row.get(name)
        # exit 3: a plan the cell cannot execute, still written for inspection
        if done is None or (done["status"] != "ok"
                            and not (name == "plan" and done["status"] == "exit 3")):
            break
    report_path = job / "report.json"
    report = json.loads(report_path.read_text()) if report_path.is_file() else {}
    row["metrics"] = _metrics(report)
    return row


def _missing(x: Any) -> bool:
    """No value: not measured (None) or nothing to measure it on (nan, e.g. no stripe layer)."""
    return x is None or (isinstance(x, float) and math.isnan(x))


def _pct(x: Any) -> str:
    return "" if _missing(x) else f"{100 * x:.1f}"


def _num(x: Any, fmt: str = ".2f") -> str:
    return "" if _missing(x) else format(x, fmt)


def table(rows: list[dict[str, Any]]) -> str:
    """The markdown table: one row per model."""
    head = ("| model | slice | plan | inspect | tets | layers | H CV | H max mm | "
            "gap/overlap contour % | gap/overlap stripe % | width p90 contour/stripe % | "
            "volume err % | alpha deg | clearance mm | speed kept % | infill % | pores % | "
            "surface err mm |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        m = r["metrics"]

        def step(name: str, r: dict[str, Any] = r) -> str:
            s = r.get(name)
            if s is None:
                return "-"
            text = f"{s['status']}{' (--repair)' if s.get('followed_fix') else ''} {s['s']:.0f} s"
            return text if not s["reason"] else f"{text}: {s['reason'][:90]}"

        alpha = ("" if m["alpha_min"] is None
                 else f"{m['alpha_min']:.1f}-{m['alpha_max']:.1f}")
        lines.append(
            f"| {r['model']} | {step('slice')} | {step('plan')} | {step('inspect')} | "
            f"{m['tets'] or ''} | {m['layers'] or ''} | {_num(m['height_cv'])} | "
            f"{_num(m['height_max_mm'])} | {_pct(m['gap_contour'])}/{_pct(m['overlap_contour'])} | "
            f"{_pct(m['gap_stripe'])}/{_pct(m['overlap_stripe'])} | "
            f"{_pct(m['width_p90_contour'])}/{_pct(m['width_p90_stripe'])} | "
            f"{_num(None if _missing(m['volume_error']) else 100 * m['volume_error'])} | {alpha} | "
            f"{_num(m.get('min_clearance_mm'), '.1f')} | {_pct(m['speed_within_5pct'])} | "
            f"{_pct(m['interior_infill'])} | {_pct(m['pores'])} | "
            f"{_num(m['surface_error_mm'], '.3f')} |")
    return "\n".join(lines)


def _merge(results: Path, row: dict[str, Any] | None = None) -> dict[str, Any]:
    """The rows of ``results`` (model -> row), with ``row`` written into it if given. Under
    a lock and re-read each time: runs over different models may share one OUT (steps of a
    subset of models at a time, in parallel)."""
    with open(results.with_suffix(".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        rows: dict[str, Any] = {}
        if results.is_file():
            rows = {r["model"]: r for r in json.loads(results.read_text())}
        if row is not None:
            rows[row["model"]] = row
            tmp = results.with_suffix(".tmp")
            tmp.write_text(json.dumps(list(rows.values()), indent=1))
            tmp.replace(results)
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--models", nargs="*", help="model names (file stems); default: all")
    ap.add_argument("--size", type=float, default=40.0, help="largest extent, mm")
    ap.add_argument("--steps", default=",".join(STEPS),
                    help="which of slice,plan,inspect to run; the others keep the previous "
                         "run's results in OUT (e.g. plan,inspect after a planner change)")
    ap.add_argument("--voxel", type=float, default=0.4, help="mesp inspect --voxel, mm")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "real_models")
    ap.add_argument("--timeout", type=float, default=900.0, help="per step, s")
    ap.add_argument("--shared", type=Path, default=SHARED_MODELS,
                    help="folder of the shared real models")
    ap.add_argument("--extra", nargs=argparse.REMAINDER, default=[],
                    help="more mesp slice arguments (the rest of the line)")
    ap.add_argument("--table", action="store_true",
                    help="run nothing: the table again from OUT (metrics re-read from each "
                         "job's report.json)")
    args = ap.parse_args(argv)
    steps = tuple(s.strip() for s in args.steps.split(",") if s.strip())
    if not steps or any(s not in STEPS for s in steps):
        ap.error(f"--steps takes names from {','.join(STEPS)}")
    if args.table:
        steps = ()
    corpus = shared_models(args.shared) + generated_models(args.out / "generated")
    order = {m.name: i for i, m in enumerate(corpus)}
    if args.models:
        corpus = [m for m in corpus if m.name in set(args.models)]
    results = args.out / "results.json"
    args.out.mkdir(parents=True, exist_ok=True)
    rows = _merge(results)
    for m in corpus:  # results.json after each model, so a stopped run keeps what it did
        if args.table:
            if m.name in rows:
                report = args.out / m.name / "report.json"
                rows[m.name]["metrics"] = _metrics(
                    json.loads(report.read_text()) if report.is_file() else {})
            continue
        row = run_model(m, args.out, args.size, args.timeout, args.extra, steps, args.voxel,
                        rows.get(m.name))
        rows = _merge(results, row)
    text = table(sorted(rows.values(), key=lambda r: order.get(r["model"], len(order))))
    (args.out / "table.md").write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
