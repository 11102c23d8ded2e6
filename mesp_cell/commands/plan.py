"""`mesp plan DIR [--cell CELL.toml]`: toolpath -> timed UR5e joint trajectory."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

from mesp_cell.console import ConsoleProgress
from slicer.errors import InputError

HELP = """\
Plan the UR5e motion for a sliced job (paper sections 3.1 and 5.2).

Reads DIR/toolpath.npz, fills the gel to 15 mm above the part (cell: fit_gel, gel_cover_mm),
places the model in the gel tank (searching position and rotation for the best clearance),
turns the printing direction towards vertical where following it would bring the wrist near
the base axis (up to upright_max_deg, alpha kept within range), orients the nozzle along
-normal (alpha = 90 deg; only where limits, singularities or
collisions demand, leaned about the direction of motion up to lean_max_deg, which keeps alpha,
or tilted within [70, 110] deg, the smallest deviation first), solves the joint motion by
damped-least-squares differential kinematics and times it within the joint velocity and
acceleration limits at the toolpath speed. Writes DIR/trajectory.npz, the "plan" section of
DIR/report.json and figures/plan_*.png. The cell (robot base, tool, tank, gel, limits) is the
bundled default (planner/cells/default.toml) overridden by --cell.
"""


def register(sub: Any) -> None:
    """Add the `plan` sub-command."""
    p = sub.add_parser(
        "plan",
        help="toolpath -> timed joint trajectory for the UR5e",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("dir", type=Path, metavar="DIR", help="job directory with toolpath.npz")
    p.add_argument("--cell", type=Path, metavar="CELL.toml",
                   help="cell description overriding the bundled default")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--render", action="store_true",
                   help="also render the twin at the first sample (needs MUJOCO_GL=egl/osmesa)")
    p.add_argument("--quiet", action="store_true", help="no progress display")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Plan the job in ``args.dir`` and print a one-line summary."""
    from planner.cell import load_cell
    from planner.other_cells import checked_fix, try_cells
    from planner.plan import plan
    from planner.status import PlanStatus, Refused
    from slicer.report import update_report
    from slicer.stages import Toolpath

    if args.render:
        # the GL backend must be chosen before mujoco is first imported; EGL is headless
        os.environ.setdefault("MUJOCO_GL", "egl")
    job_dir: Path = args.dir
    if not job_dir.is_dir():
        raise InputError(f"job directory {job_dir} does not exist", "run `mesp slice` first")
    cell = load_cell(args.cell)
    progress = ConsoleProgress(quiet=args.quiet)
    start = time.perf_counter()
    toolpath = Toolpath.load(job_dir)
    progress.info(f"planning {len(toolpath)} waypoints in {job_dir}")
    try:
        result = plan(toolpath, cell, progress=progress)
    except Refused as exc:
        # refused before motion: the fix names another bundled cell only if it plans there
        progress.info(f"refused ({exc.cause}); trying the other bundled cells")
        raise InputError(exc.problem, checked_fix(try_cells(toolpath, args.cell), exc.fix)) \
            from exc
    result.trajectory.save(job_dir)
    report = dict(result.report)
    if not args.no_figures:
        from planner.plots import write_plan_figures

        figures = write_plan_figures(result, job_dir / "figures")
        report["figures"] = [str(p.relative_to(job_dir)) for p in figures]
    if args.render:
        from sim.render import render_png
        from sim.twin import Twin

        shot = render_png(Twin(cell), result.trajectory.q[0], job_dir / "figures" / "plan_twin.png")
        if shot.path is None:
            progress.info(f"render skipped: {shot.message}")
        report["render"] = str(shot.path) if shot.path else shot.message
    report["total_s"] = time.perf_counter() - start
    update_report(job_dir, {"plan": report})
    summary = {
        "status": str(report["status"]),
        "duration_s": round(report["duration_s"], 2),
        "min_clearance_mm": report["min_clearance_mm"],
        "unreachable": report["unreachable"]["count"],
        "over_deposition_mm3": round(report["over_deposition"]["volume_mm3"], 3),
    }
    progress.info(f"done: {json.dumps(summary)}; trajectory in {job_dir / 'trajectory.npz'}")
    if result.status != PlanStatus.OK:
        # the trajectory is kept for inspection, but a cell would refuse it: say why and what
        # works (another bundled cell, tried here), then fail
        progress.info(f"not executable ({result.status}); trying the other bundled cells")
        fix = checked_fix(try_cells(toolpath, args.cell), _fix(result))
        print(f"mesp: error: the plan cannot be executed ({result.status}): {result.message}; "
              f"{fix}", file=sys.stderr)
        return 3
    return 0


def _fix(result: Any) -> str:
    """What to do about a plan the cell cannot execute: the fix of its first refused
    waypoint's cause, else of its status."""
    from planner.status import FIXES, PlanStatus

    if result.cause is not None:
        return str(FIXES[result.cause])
    if result.status in (PlanStatus.ENTRY_BLOCKED, PlanStatus.EXIT_BLOCKED, PlanStatus.SWING):
        return "move the part ([placement] offset_mm, yaw_deg) or the robot base"
    return "move the part or use a cell that reaches it"
