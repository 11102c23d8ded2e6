"""`mesp check MODEL [--job JOB.toml] [--cell CELL.toml]`: does the part fit, before slicing."""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from core.errors import InputError

# Of the seconds `mesp check` answers in, those a wrap by fTetWild may take to check that
# --repair works (a fill, a split and join, or a stored wrap is made or read at once).
REPAIR_SECONDS = 10.0

HELP = """\
Preflight a model in seconds, without tetrahedralising or slicing it: whether it fits the
cell (footprint in the tank, height under the gel, the arm's reach with the nozzle vertical),
whether its units look wrong (a part a few mm or several m across; --units suggested where
another unit fits), whether its standing walls hold the toolpath's line (a size that does
suggested, checked), and which critical surfaces the slicer would fix (one line each, and a
PNG of the chosen patches). A surface `mesp slice` would refuse as open or non-manifold is
reported with whether `mesp slice --repair` makes it a solid (tried here within a few seconds,
else said not checked), and the rest is checked on the repaired surface. Exit 0 when
everything fits, 1 when something does not (each problem says its fix).
"""


def register(sub: Any) -> None:
    """Add the `check` sub-command."""
    p = sub.add_parser(
        "check",
        help="preflight: does the model fit the cell, units, critical surfaces (seconds)",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("model", type=Path, help="STL/OBJ/PLY surface")
    p.add_argument("--job", type=Path, metavar="JOB.toml", help="job file (units, critical)")
    p.add_argument("--cell", type=Path, metavar="CELL.toml",
                   help="cell description overriding the bundled default")
    p.add_argument("--units", choices=["mm", "cm", "m", "in"], help="units of the model file")
    p.add_argument("--scale-to", type=float, metavar="MM",
                   help="scale the model uniformly so its largest extent is MM, as `mesp slice "
                   "--scale-to` does")
    p.add_argument("--critical", action="append", metavar="SELECTOR",
                   help="critical region selector as for `mesp slice` (repeatable)")
    p.add_argument("--figure", type=Path, metavar="PNG",
                   help="where to draw the critical patches (default: MODEL-check.png in the "
                   "current directory)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print one line per finding; exit 1 if the part does not fit."""
    from mesp_cell import profiles
    from planner.cell import load_cell
    from planner.other_cells import bundled_cells
    from planner.preflight import Finding, preflight
    from planner.preflight_figure import critical_patches_png
    from slicer.config import load_job
    from slicer.extrusion import load_profile
    from slicer.mesh_io import Surface, load_surface
    from slicer.repair import repairable
    from slicer.repair_offer import offer_fix, repair_within
    from slicer.surface_refusal import SurfaceRefused
    from slicer.toolpath.thin_features import THINNEST

    start = time.perf_counter()
    job = load_job(args.job)
    cell_name = profiles.default_cell()
    overrides: dict[str, dict[str, Any]] = {
        "extrusion": {"profile": profiles.resolve(job.extrusion.profile, cell_name)}}
    if args.units or args.scale_to is not None:
        overrides["model"] = {
            **({"units": args.units} if args.units else {}),
            **({"scale_to_mm": args.scale_to} if args.scale_to is not None else {}),
        }
    if args.critical:
        overrides["slicing"] = {"critical": tuple(args.critical)}
    job = job.with_overrides(**overrides)
    line = load_profile(job.extrusion.profile).width(job.slicing.layer_height_mm)
    width = float(THINNEST * line)  # the narrowest line the toolpath lays
    cell = load_cell(args.cell)
    # any size is read: a part of 8 m or 8 um is what the units finding is for
    units = replace(job.model, max_size_mm=1e12, min_size_mm=1e-12)
    mesh: list[Finding] = []
    try:
        surface = load_surface(args.model, units)
    except InputError as exc:
        if not isinstance(exc, SurfaceRefused) or not repairable(exc):
            raise
        outcome = repair_within(args.model, units, REPAIR_SECONDS, exc.reason)
        fix = offer_fix(exc, outcome, REPAIR_SECONDS, "slice with --repair")
        if not isinstance(outcome, Surface):  # the rest needs a surface that loads
            raise InputError(exc.problem, fix) from exc
        surface = outcome
        mesh.append(Finding("mesh", False, f"{exc.problem}; {fix}"))
    others = {name: load_cell(path) for name, path in bundled_cells()
              if not (path is None and args.cell is None)
              and not (path is not None and args.cell is not None
                       and path.resolve() == args.cell.resolve())}
    result = preflight(surface, job, cell, width, others)
    findings = (*mesh, *result.findings)
    for f in findings:
        print(f"{f.topic:>8}: {'ok' if f.ok else 'PROBLEM'}: {f.text}")
    figure = args.figure or Path(f"{args.model.stem}-check.png")
    labels = [f"{k}: {r.selector}, {r.area:.0f} mm^2"
              for k, r in enumerate(result.selection.regions)]
    try:
        critical_patches_png(result.patches, result.face_region, labels, figure)
        print(f"  figure: {figure} (critical patches in colour); checked in "
              f"{time.perf_counter() - start:.1f} s")
    except OSError as exc:
        raise InputError(f"cannot write {figure} ({exc.strerror})",
                         "give a writable path with --figure") from exc
    problems = [f for f in findings if not f.ok]
    if problems:
        print(f"mesp: error: {problems[0].text}", file=sys.stderr)
        return 1
    return 0
