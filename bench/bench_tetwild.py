"""fTetWild (pytetwild) at ~250k tets: default settings against faster ones.

Each setting runs in its own child process so its peak memory (``ru_maxrss``) is its own.
The edge length giving ~``--tets`` tets is found per model and setting from one coarse
pilot run (tet count ~ edge^-3), so every setting is timed at about the same tet count.
Reported per run: wall and CPU time of fTetWild, peak memory, tets, mean edge, min dihedral
angle, fraction of tets with a dihedral angle under 10 deg, mean and worst radius ratio,
volume error against the surface.

    .venv/bin/python bench/bench_tetwild.py           # socket + aorta: direct vs refined
    .venv/bin/python bench/bench_tetwild.py --models socket --settings defaults fast
    .venv/bin/python bench/bench_tetwild.py --edge socket=3.0     # skip the pilot run

Findings (2026-11-22, 2 shared cores, load average 4-10, so CPU seconds are the numbers to
compare; wall times were 1.5-4x longer):

- ``coarsen = true`` is the main cost: socket at edge 6.64 mm, 1 thread, CPU s / tets /
  worst radius ratio: defaults 69.9 / 15.0 k / 0.087; no-coarsen 30.0-32.3 / 22.3 k / 0.41-0.44.
- At ~250 k tets the 80 optimisation passes dominate: socket, edge 2.95 mm, all cores:
  no-coarsen (80 passes, stop 10) > 580 s CPU, not finished after 18 min wall;
  no-coarsen-fast (10 passes, stop 20) 153 s CPU, 227 k tets, 1.24 GB, mean edge 3.05 mm,
  min dihedral 3.8 deg, slivers (< 10 deg) 0.004 %, mean/worst radius ratio 0.83/0.026,
  volume error -0.08 %. Graded (edge 3.27 mm, 185 k tets): 10 passes 176 s, 80 passes 233 s.
- The outside sizing field (``grading``) gave no consistent gain (fTetWild applies it only
  after its first passes); a steep one (1.0) makes slivers.
- Aorta (thin wall, large surface) at edge 1.37 mm (~250 k tets) did not finish in 900 s wall.
- fTetWild is not deterministic across thread counts; the single worst tet varies a lot
  between runs, the sliver fraction and mean quality much less.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from core.configtools import build  # noqa: E402
from slicer.config import MeshConfig, default_data  # noqa: E402

# name -> ([mesh] overrides of the defaults file, grading of the outside sizing field)
SETTINGS: dict[str, tuple[dict[str, object], float]] = {
    "defaults": ({"refine": 0}, 0.0),
    "no-coarsen": ({"coarsen": False, "refine": 0}, 0.0),
    "graded": ({"coarsen": False, "refine": 0}, 0.5),
    "no-coarsen-fast": ({"coarsen": False, "optimize_iterations": 10, "stop_energy": 20.0,
                         "refine": 0}, 0.0),
    # the defaults file since session 8: fTetWild at twice the edge, one red refinement
    "refined": ({"coarsen": False, "optimize_iterations": 10, "stop_energy": 20.0,
                 "refine": 1}, 0.0),
    "fast": ({"coarsen": False, "optimize_iterations": 20, "stop_energy": 15.0, "refine": 0},
             0.5),
    "fast-eps2": ({"coarsen": False, "optimize_iterations": 10, "stop_energy": 20.0,
                   "refine": 0}, 0.5),
    "min-opt": ({"coarsen": False, "optimize_iterations": 3, "stop_energy": 20.0, "refine": 0},
                0.5),
    "fastest": (
        {"coarsen": False, "optimize_iterations": 10, "stop_energy": 20.0, "epsilon": 3e-3,
         "refine": 0},
        0.5,
    ),
    "fastest-steep": (
        {"coarsen": False, "optimize_iterations": 10, "stop_energy": 20.0, "epsilon": 3e-3,
         "refine": 0},
        1.0,
    ),
}


def mesh_config(name: str, edge: float) -> MeshConfig:
    data = {**default_data()["mesh"], **SETTINGS[name][0], "edge_length_mm": edge}
    return build(MeshConfig, data, "mesh")


def run_one(model: str, setting: str, edge: float, threads: int) -> dict[str, object]:
    """Mesh one model with one setting in this process; returns the measurements."""
    from slicer.mesh_io import load_surface
    from slicer.tetrahedralize import tetrahedralize

    surface = load_surface(ROOT / "examples" / f"{model}.stl")
    before = resource.getrusage(resource.RUSAGE_SELF)
    start = time.perf_counter()
    config = mesh_config(setting, edge)
    _, stats = tetrahedralize(surface, config, grading=SETTINGS[setting][1], threads=threads)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_SELF)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {
        "model": model,
        "setting": setting,
        "edge_mm": edge,
        "threads": threads,
        "wall_s": round(wall, 1),
        "cpu_s": round(cpu, 1),
        "peak_mb": round(after.ru_maxrss / 1024.0),
        "tets": stats.tets,
        "mean_edge_mm": round(stats.mean_edge_mm, 3),
        "min_dihedral_deg": round(stats.min_dihedral_deg, 2),
        "slivers": float(f"{stats.sliver_fraction:.1e}"),
        "mean_quality": round(stats.mean_quality, 3),
        "worst_quality": round(stats.worst_quality, 4),
        "volume_error": float(f"{stats.volume_error:.2e}"),
        "ftetwild_tets": stats.ftetwild_tets,
        "ftetwild_s": round(stats.ftetwild_seconds, 1),
    }


def child(
    model: str, setting: str, edge: float, timeout: float, threads: int = 0
) -> dict[str, object]:
    cmd = [sys.executable, __file__, "--one", model, setting, str(edge), str(threads)]
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=True)
    except subprocess.TimeoutExpired:
        return {"model": model, "setting": setting, "edge_mm": edge, "error": f">{timeout:.0f} s"}
    except subprocess.CalledProcessError as exc:
        return {"model": model, "setting": setting, "edge_mm": edge, "error": exc.stderr[-300:]}
    return json.loads(out.stdout.strip().splitlines()[-1])


def edge_for(model: str, setting: str, target: int, timeout: float, threads: int) -> float:
    """Edge length giving ~target tets with this setting, from one coarse pilot run."""
    from slicer.mesh_io import load_surface

    surface = load_surface(ROOT / "examples" / f"{model}.stl")
    # Pilot at ~1/8 of the target (fTetWild keeps ~0.15 edge^3 of solid per tet).
    pilot = round((surface.volume_mm3 / (0.15 * target / 8.0)) ** (1.0 / 3.0), 2)
    result = child(model, setting, pilot, timeout, threads)
    if "error" in result:
        raise SystemExit(f"pilot run failed: {result}")
    print(
        f"# pilot {model} {setting}: edge {pilot} mm -> {result['tets']} tets, "
        f"{result['wall_s']} s wall, {result['cpu_s']} s cpu",
        flush=True,
    )
    return round(pilot * (int(str(result["tets"])) / target) ** (1.0 / 3.0), 2)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--models", nargs="+", default=["socket", "aorta"])
    parser.add_argument(
        "--settings", nargs="+", default=["no-coarsen-fast", "refined"], choices=list(SETTINGS)
    )
    parser.add_argument("--tets", type=int, default=250_000, help="target tet count")
    parser.add_argument("--edge", action="append", default=[], help="MODEL=MM, skip the pilot")
    parser.add_argument("--timeout", type=float, default=900.0, help="per run, s")
    parser.add_argument(
        "--threads",
        type=int,
        default=0,
        help="fTetWild threads, 0 = all cores (use 1 to "
        "compare CPU times on a busy machine: idle worker threads spin and inflate them)",
    )
    parser.add_argument("--one", nargs="+", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        model, setting, edge, *threads = args.one
        print(json.dumps(run_one(model, setting, float(edge), int(threads[0] if threads else 0))))
        return
    edges = {k: float(v) for k, v in (item.split("=") for item in args.edge)}
    keys = [
        "setting",
        "edge_mm",
        "threads",
        "wall_s",
        "cpu_s",
        "peak_mb",
        "tets",
        "mean_edge_mm",
        "min_dihedral_deg",
        "slivers",
        "mean_quality",
        "worst_quality",
        "volume_error",
        "ftetwild_tets",
        "ftetwild_s",
    ]
    for model in args.models:
        print(f"## {model}, target {args.tets} tets", flush=True)
        print(" | ".join(keys), flush=True)
        for setting in args.settings:
            edge = edges.get(model) or edge_for(
                model, setting, args.tets, args.timeout, args.threads
            )
            row = child(model, setting, edge, args.timeout, args.threads)
            if "error" in row:
                print(f"{setting} | {edge} | error: {row['error']}", flush=True)
            else:
                print(" | ".join(str(row[k]) for k in keys), flush=True)


if __name__ == "__main__":
    main()
