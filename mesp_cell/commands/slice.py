"""`mesp slice MODEL [--job JOB.toml] --out DIR`: mesh -> tets -> curved layers -> toolpath."""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from core.errors import InputError
from mesp_cell.console import ConsoleProgress
from slicer.checks import critical_line, job_notes
from slicer.config import JobConfig, load_job
from slicer.summary import SliceSummary

if TYPE_CHECKING:
    from planner.cell import CellConfig

HELP = """\
Slice a solid model into curved layers and a width-constrained toolpath (paper section 4).

Reads an STL/OBJ/PLY surface (or a .msh/.vtk/.vtu tet mesh), tetrahedralises it, optimises the
slicing field, extracts the layers and computes the toolpath. Writes into DIR:
tetmesh.npz, field.npz, layers.npz, toolpath.npz, report.json, model.ply, job.toml (the effective
settings), layers_ply/ (one PLY per layer), layers_txt/ (x y z nx ny nz W H v per layer) and
figures/ (PNG). Settings come from the defaults, then --job, then the flags below.
"""


def register(sub: Any) -> None:
    """Add the `slice` sub-command."""
    p = sub.add_parser(
        "slice",
        help="mesh -> tets -> curved layers -> toolpath",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("model", type=Path, help="STL/OBJ/PLY surface, or .msh/.vtk/.vtu tet mesh")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="job directory to write")
    p.add_argument(
        "--job", type=Path, metavar="JOB.toml", help="job file (see slicer/defaults.toml)"
    )
    p.add_argument("--units", choices=["mm", "cm", "m", "in"], help="units of the model file")
    p.add_argument("--scale-to", type=float, metavar="MM",
                   help="scale the model uniformly so its largest extent is MM")
    p.add_argument("--layer-height", type=float, metavar="MM", help="target layer height H")
    p.add_argument("--edge-length", type=float, metavar="MM", help="tet mesh target edge length")
    p.add_argument(
        "--critical",
        action="append",
        metavar="SELECTOR",
        help="critical region: bottom[:DEG] | top[:DEG] | normal:X,Y,Z[:DEG], optionally "
        "with position conditions on each patch's centre, e.g. bottom:30@z<1 (repeatable; "
        "replaces the job file's list)",
    )
    p.add_argument("--planar", action="store_true", help="planar slicing (g = z)")
    p.add_argument("--repair", action="store_true",
                   help="close every hole of an open surface (a scan), or wrap an open or "
                   "non-manifold one with fTetWild's winding-number test, before slicing, and "
                   "say what changed")
    p.add_argument(
        "--no-baselines",
        action="store_true",
        help="skip the width error without deformation and of the Poisson alternative "
        "(report-only comparisons, about a third of the toolpath's work)",
    )
    p.add_argument(
        "--until",
        choices=["tetmesh", "layers", "toolpath"],
        default="toolpath",
        help="stop after this stage (default: toolpath)",
    )
    p.add_argument("--cell", type=Path, metavar="CELL.toml", default=None,
                   help="cell file the job is for: its printing-angle range sets the "
                   "toolpath's step limits, its path accelerations the speed ramps "
                   "(default: the bundled cell)")
    p.add_argument("--on", metavar="CELL", default=None,
                   help="the cell whose active extrusion profile the job's profile \"active\" "
                   "is (`mesp profile`; default: the only cell running, else 'sim')")
    p.add_argument("--quiet", action="store_true", help="no progress display")
    p.set_defaults(func=run)


def job_from_args(args: argparse.Namespace) -> JobConfig:
    """The job file (or defaults) with the command-line overrides applied and validated."""
    from mesp_cell import profiles

    job = load_job(args.job)
    cell = getattr(args, "on", None) or profiles.default_cell()
    overrides: dict[str, dict[str, Any]] = {
        "extrusion": {"profile": profiles.resolve(job.extrusion.profile, cell)}}
    if args.units or args.scale_to is not None:
        overrides["model"] = {
            **({"units": args.units} if args.units else {}),
            **({"scale_to_mm": args.scale_to} if args.scale_to is not None else {}),
        }
    if args.edge_length is not None:
        overrides["mesh"] = {"edge_length_mm": args.edge_length}
    slicing: dict[str, Any] = {}
    if args.layer_height is not None:
        slicing["layer_height_mm"] = args.layer_height
    if args.critical:
        slicing["critical"] = tuple(args.critical)
    if args.planar:
        slicing["planar"] = True
    if slicing:
        overrides["slicing"] = slicing
    if args.no_baselines:
        overrides["toolpath"] = {"measure_baselines": False}
    return job.with_overrides(**overrides) if overrides else job


def _too_big(cell: CellConfig, bbox_mm: Sequence[float]) -> str | None:
    """Why a part of ``bbox_mm`` (3,) mm would not fit ``cell`` (its tank or gel), or None."""
    import numpy as np

    from planner.preflight import fits_gel, fits_tank

    size = np.asarray(bbox_mm, dtype=float)
    if fits_tank(cell, size) is None:
        return (f"{size[0]:.0f} x {size[1]:.0f} mm, it would not fit the tank "
                f"({cell.tank.inner_size_mm[0]:.0f} x {cell.tank.inner_size_mm[1]:.0f} mm)")
    if not fits_gel(cell, float(size[2])):
        return (f"{size[2]:.0f} mm tall, it would stand out of the gel "
                f"({cell.tank.gel_fill_mm:.0f} mm)")
    return None


def run(args: argparse.Namespace) -> int:
    """Run the slicing pipeline and print a short summary."""
    from slicer.pipeline import slice_model
    from slicer.toolpath.thin_features import ThinWallsError

    job = job_from_args(args)
    if args.out.exists() and not args.out.is_dir():
        raise InputError(f"--out {args.out} is a file", "name a directory")
    progress = ConsoleProgress(quiet=args.quiet)
    progress.info(f"slicing {args.model} -> {args.out}")
    from planner.cell import load_cell

    cell = load_cell(args.cell)
    alpha = cell.planning.alpha_range
    try:
        report = slice_model(args.model, args.out, job, progress=progress, until=args.until,
                             alpha=alpha, repair=args.repair, accel=cell.planning.path_accel)
    except ThinWallsError as exc:
        raise exc.with_cell(_too_big(cell, exc.bbox_mm)) from exc
    except InputError as exc:
        from slicer.repair import repairable
        from slicer.repair_offer import repair_offer

        if args.repair or not repairable(exc):
            raise
        raise repair_offer(args.model, job.model, exc) from exc
    summary = SliceSummary.of(report).as_dict()
    progress.info(f"done: {json.dumps(summary)}; report in {args.out / 'report.json'}")
    line = critical_line(report)
    if line is not None:
        progress.info(line)
    if args.until in (None, "toolpath") and (args.out / "toolpath.npz").is_file():
        # what the planner will refuse in any placement, known from the toolpath alone
        from core.report import update_report
        from core.stages import Toolpath
        from planner.printability import check

        section, _ = check(Toolpath.load(args.out), cell)
        report = update_report(args.out, {"printability": section})
    thin = report.get("toolpath", {}).get("too_thin", {})
    if thin.get("excess_share", 0.0) > thin.get("limit", float("inf")):
        # printed thicker (thin_walls = "thicken"): the size the note names, against the cell
        from core.report import update_report

        bbox = report["model"]["bbox_mm"]
        grow = float(thin["fits_at_size_mm"]) / max(bbox)
        section = {**report["toolpath"],
                   "too_thin": {**thin, "too_big": _too_big(cell, [grow * b for b in bbox])}}
        report = update_report(args.out, {"toolpath": section})
    for note in job_notes(report):  # even with --quiet: they may need acting on
        print(f"note: {note}", flush=True)
    return 0
