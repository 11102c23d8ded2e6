"""`mesp inspect DIR`: simulated deposition of a sliced job and its print quality
(``sim.pipeline.inspect_job``), checked arguments in, the comparison table out."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

import numpy as np

from core.errors import InputError
from core.report import read_report
from core.stages import Toolpath
from mesp_cell.console import ConsoleProgress
from sim.print_summary import PrintSummary
from sim.voxel_choice import AUTO_VOXEL_BUDGET, DEFAULT_VOXEL_MM


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``inspect`` sub-command."""
    p = subparsers.add_parser(
        "inspect",
        help="simulate the deposition of a sliced job: infill, pores, surface error",
        description=(
            "Virtual print of DIR/toolpath.npz into the support gel on a voxel grid (constant "
            "extrusion rate, filament morphology from the extrusion profile, immiscible ink "
            "whose excess spreads into nearby free space), measured against DIR/model.ply: "
            "infill ratio, pore ratio, over-deposition, surface error (mean, p95, max) and "
            "per-layer over/under-deposition. Optionally the same for a planar baseline "
            "(--baseline planar: planar layers at the job's median layer height, in both line "
            "width modes, overlap W = beta w_f and volume-preserving W = C / (H v), the latter "
            "flushed like a curved job when DIR has tetmesh.npz; the better one is the baseline), "
            "PrusaSlicer's print of DIR/model.ply (--baseline prusaslicer: same layer height, "
            "lines at the overlap W = beta w_f, one constant speed, 100% rectilinear infill, "
            "G-code written to DIR/baseline_prusaslicer.gcode; `make baselines` installs "
            "PrusaSlicer) or a commercial slicer's G-code (--gcode FILE), side by side. "
            "With --as-planned also the print as DIR/trajectory.npz moves the nozzle: where "
            "the planner slows down, the cell scales the extruder's rate with the arm's speed "
            "(lead-compensated, the screw's first-order lag simulated), or, with "
            "--constant-flow, keeps C and deposits more. "
            "Adds an 'inspect' section to DIR/report.json and writes inspect_*.png into DIR."
        ),
    )
    p.add_argument("dir", metavar="DIR", type=Path, help="job directory written by `mesp slice`")
    p.add_argument("--voxel", type=float, default=None, metavar="MM",
                   help=f"voxel edge in mm (default {DEFAULT_VOXEL_MM}, coarser for models too "
                        f"large for {AUTO_VOXEL_BUDGET:,} voxels)")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--baseline", choices=["planar", "prusaslicer"],
                       help="also print the model with planar layers (our planar slicer, or "
                            "PrusaSlicer's CLI on the job's model) and compare")
    group.add_argument("--gcode", type=Path, metavar="FILE",
                       help="also print this planar G-code (Cura/PrusaSlicer) and compare")
    p.add_argument("--profile", default=None, metavar="NAME",
                   help="extrusion profile name or TOML path (default: the profile the job was "
                   "sliced with, DIR/profile.toml)")
    p.add_argument("--baseline-height", type=float, default=None, metavar="MM",
                   help="planar baseline layer height (default: median toolpath height)")
    p.add_argument("--baseline-beta", type=float, default=None, metavar="B",
                   help="planar baseline overlap ratio (default: sqrt(pi)/2, volume-matching, "
                        "in overlap mode and for PrusaSlicer; the profile's beta in volume "
                        "mode)")
    p.add_argument("--baseline-width", choices=["overlap", "volume", "both"], default="both",
                   help="planar baseline line width rule: W = beta w_f (overlap), "
                        "W = C / (H v) (volume), or both, keeping the better (default both; "
                        "PrusaSlicer always uses overlap)")
    p.add_argument("--flush", action="store_true",
                   help="first move the job's exposed waypoints inwards so filaments are flush "
                        "with the model (slicer.toolpath.flush; needs DIR/tetmesh.npz; ignored "
                        "when mesp slice already did it)")
    p.add_argument("--filament", type=float, default=1.75, metavar="MM",
                   help="filament diameter the G-code's E refers to (0 = volumetric E)")
    p.add_argument("--as-planned", action="store_true",
                   help="also print at the speeds the planned trajectory (DIR/trajectory.npz, "
                        "from mesp plan) moves each segment at, and compare")
    p.add_argument("--constant-flow", action="store_true",
                   help="with --as-planned: the extruder keeps its rate C where the arm slows "
                        "down (the cell scales it with the arm's speed)")
    p.add_argument("--flow-lead", type=float, default=0.3, metavar="S",
                   help="with --as-planned: how far ahead the rate is commanded (s, default "
                        "0.3: the launch files' lead_s)")
    p.add_argument("--flow-tau", type=float, default=0.2, metavar="S",
                   help="with --as-planned: time constant of the extruder's flow response "
                        "(s, default 0.2: the emulated extruder's)")
    p.add_argument("--no-figures", action="store_true", help="do not write the PNG pictures")
    p.add_argument("--quiet", action="store_true", help="no progress display")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute `mesp inspect`."""
    # the simulation (numba, trimesh, matplotlib) loads only when the command runs
    from sim.baseline_prints import BaselineOptions, check_prusaslicer
    from sim.pipeline import InspectOptions, inspect_job

    _check(args)
    baseline = BaselineOptions(kind=args.baseline, gcode=args.gcode,
                               height_mm=args.baseline_height, beta=args.baseline_beta,
                               width=args.baseline_width, filament_mm=args.filament)
    if args.baseline == "prusaslicer":
        check_prusaslicer(baseline)
    options = InspectOptions(voxel_mm=args.voxel, profile=args.profile, baseline=baseline,
                             flush=args.flush, as_planned=args.as_planned,
                             constant_flow=args.constant_flow, flow_lead_s=args.flow_lead,
                             flow_tau_s=args.flow_tau, figures=not args.no_figures)
    console = ConsoleProgress(quiet=args.quiet)
    result = inspect_job(Path(args.dir), options, console, console)
    print(_table(result.columns))
    return 0


def _check(args: argparse.Namespace) -> None:
    """One-line InputErrors for a job directory or flags the pipeline cannot use."""
    job = Path(args.dir)
    if not job.is_dir():
        raise InputError(f"job directory {job} does not exist", "run mesp slice MODEL --out DIR")
    if not (job / Toolpath.FILE).is_file():
        raise InputError(f"{job} has no {Toolpath.FILE}", f"run mesp slice MODEL --out {job}")
    if not (job / "model.ply").is_file():
        # The model as sliced (mm, model frame): metrics and PrusaSlicer both need it.
        source = read_report(job).get("job", {}).get("model_file") or "MODEL"
        raise InputError(f"{job} has no model.ply (the model as mesp slice read it)",
                         f"re-run mesp slice {source} --out {job}")
    if args.voxel is not None and not (np.isfinite(args.voxel) and 0.01 <= args.voxel <= 10.0):
        raise InputError(f"--voxel {args.voxel} is out of range", "use 0.01 to 10 mm, e.g. 0.25")
    if args.flush and not (job / "tetmesh.npz").is_file():
        raise InputError(f"--flush needs {job / 'tetmesh.npz'}",
                         f"re-run mesp slice MODEL --out {job}")
    if args.as_planned and not (job / "trajectory.npz").is_file():
        raise InputError(f"--as-planned needs {job / 'trajectory.npz'}", f"run mesp plan {job}")
    for name, value in (("--flow-lead", args.flow_lead), ("--flow-tau", args.flow_tau)):
        if not (np.isfinite(value) and 0.0 <= value <= 10.0):
            raise InputError(f"{name} {value} is out of range", "use 0 to 10 s, e.g. 0.2")
    if args.gcode is not None and not Path(args.gcode).is_file():
        raise InputError(f"G-code file {args.gcode} does not exist", "check the --gcode path")
    if not (np.isfinite(args.filament) and 0.0 <= args.filament <= 10.0):
        raise InputError(f"--filament {args.filament} is out of range",
                         "use a diameter of 0 to 10 mm (0: E is a volume in mm^3)")
    for name, value, lo, hi in (("--baseline-height", args.baseline_height, 0.02, 20.0),
                                ("--baseline-beta", args.baseline_beta, 0.1, 1.0)):
        if value is not None and not lo <= value <= hi:
            raise InputError(f"{name} {value} is out of range", f"use {lo} to {hi}")


def _table(columns: list[tuple[str, PrintSummary]]) -> str:
    """Side-by-side table (one column per simulated print), with the paper's numbers."""
    rows: list[tuple[str, Callable[[PrintSummary], float], str]] = [
        ("infill ratio %", lambda s: 100 * s.infill_ratio, "-"),
        ("interior infill % (1 mm)", lambda s: 100 * s.interior_infill_ratio, "99.47 (CT)"),
        ("pore ratio %", lambda s: 100 * s.pore_ratio, "0.25"),
        ("over-deposition %", lambda s: 100 * s.over_deposition, "-"),
        ("under-deposition %", lambda s: 100 * s.under_deposition, "-"),
        ("surface error mean mm", lambda s: s.surface_error_mm["mean"], "0.20 (planar 0.49)"),
        ("surface error p95 mm", lambda s: s.surface_error_mm["p95"], "-"),
        ("surface error max mm", lambda s: s.surface_error_mm["max"], "< 1.5"),
        # signed: > 0 the print bulges out of faces facing that way, < 0 it falls short
        ("  signed, up faces mm", lambda s: s.signed_error("up"), "-"),
        ("  signed, side faces mm", lambda s: s.signed_error("side"), "-"),
        ("  signed, down faces mm", lambda s: s.signed_error("down"), "-"),
    ]
    head = f"{'':24}" + "".join(f"{label:>16}" for label, _ in columns)
    lines = [head + f"   {'paper':<20}"]
    for name, get, paper in rows:
        line = f"{name:24}" + "".join(f"{get(summary):16.3f}" for _, summary in columns)
        lines.append(line + f"   {paper:<20}")
    return "\n".join(lines)
