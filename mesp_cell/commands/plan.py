"""`mesp plan DIR [--cell CELL.toml]`: toolpath -> timed UR5e joint trajectory."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from core.errors import InputError
from mesp_cell.console import ConsoleProgress

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
DIR/report.json, figures/plan_*.png and DIR/preview.html (`mesp preview`). The cell (robot
base, tool, tank, gel, limits) is the bundled default (planner/cells/default.toml) overridden
by --cell.
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
                   help="also render the twin at the first sample (figures/plan_twin.png)")
    p.add_argument("--video", action="store_true",
                   help="also render the dry run on the twin: figures/dry_run.mp4 and its "
                   "contact sheet figures/dry_run.png (docs/visual.md)")
    p.add_argument("--speedup", type=float, default=0.0, metavar="X",
                   help="video: print seconds per video second (default: a 40 s video)")
    p.add_argument("--video-size", default="640x480", metavar="WxH",
                   help="video: frame size in px (default 640x480)")
    p.add_argument("--quiet", action="store_true", help="no progress display")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Plan the job in ``args.dir`` and print a one-line summary."""
    import numpy as np

    from core.report import update_report
    from core.stages import Toolpath
    from planner.cell import load_cell
    from planner.plan import plan
    from planner.plan_summary import PlanSummary
    from planner.status import PlanStatus, Refused

    if args.render or args.video:
        from sim.gl import choose_gl

        choose_gl()  # before mujoco is first imported
    size = _size(args.video_size)
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
        # refused before motion: the fix names a planning option or another bundled cell
        # only if the job plans with it
        progress.info(f"refused ({exc.cause}); trying planning options and the other bundled "
                      "cells")
        raise InputError(exc.problem, _checked_fix(job_dir, toolpath, cell, args.cell,
                                                   exc.cause, exc.fix)) from exc
    result.trajectory.save(job_dir)
    report = dict(result.report)
    if not args.no_figures:
        from planner.plots import write_plan_figures
        from sim.preview import write_preview

        figures = write_plan_figures(result, job_dir / "figures")
        report["figures"] = [str(p.relative_to(job_dir)) for p in figures]
        report["preview"] = write_preview(toolpath, job_dir / "preview.html",
                                          result.trajectory).name
    if args.render:
        from sim.render import render_png
        from sim.twin import Twin
        from sim.video import work_view

        traj = result.trajectory
        # the arm at the first deposition, the whole arm in view
        first = np.flatnonzero(np.asarray(traj.extrude))
        lookat, extent = work_view(traj, toolpath)
        shot = render_png(Twin(cell), traj.q[first[0] if len(first) else 0],
                          job_dir / "figures" / "plan_twin.png", *size,
                          lookat + np.array([0.0, 0.0, 0.1]), max(3.0 * extent, 0.5))
        if shot.path is None:
            progress.info(f"render skipped: {shot.message}")
        report["render"] = str(shot.path) if shot.path else shot.message
    if args.video:
        report["video"] = _video(job_dir, cell, result, toolpath, args.speedup, size, progress)
    report["total_s"] = time.perf_counter() - start
    update_report(job_dir, {"plan": report})
    summary = PlanSummary.of(report).to_dict()
    progress.info(f"done: {json.dumps(summary)}; trajectory in {job_dir / 'trajectory.npz'}")
    if result.status != PlanStatus.OK:
        # the trajectory is kept for inspection, but a cell would refuse it: say why and what
        # works (another bundled cell, tried here), then fail
        progress.info(f"not executable ({result.status}); trying planning options and the "
                      "other bundled cells")
        fix = _checked_fix(job_dir, toolpath, cell, args.cell, result.cause or result.status,
                           _fix(result))
        print(f"mesp: error: the plan cannot be executed ({result.status}): {result.message}; "
              f"{fix}", file=sys.stderr)
        return 3
    return 0


def _size(text: str) -> tuple[int, int]:
    """(width, height) px of a ``WxH`` option."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        w = h = 0
    if not (16 <= w <= 1920 and 16 <= h <= 1080):
        raise InputError(f"--video-size {text} is not a frame size",
                         "write WIDTHxHEIGHT in px, e.g. 640x480 (at most 1920x1080)")
    return w, h


def _video(job_dir: Path, cell: Any, result: Any, toolpath: Any, speedup: float,
           size: tuple[int, int], progress: ConsoleProgress) -> dict[str, Any]:
    """Render the dry-run video; its report entry (or why it was skipped)."""
    import numpy as np

    from sim.twin import Twin
    from sim.video import render_video

    if speedup < 0:
        raise InputError(f"--speedup {speedup} is negative", "pass a positive speed-up")
    traj = result.trajectory
    speedup = speedup or max(1.0, traj.duration_s / 40.0)
    required = float(result.report["required_clearance_mm"])
    progress.info(f"rendering the dry run at x{speedup:g} ...")
    part = None
    if (job_dir / "model.ply").is_file():  # the surface mesp slice sliced, model frame
        import trimesh

        mesh: Any = trimesh.load(job_dir / "model.ply", force="mesh")
        part = (np.asarray(mesh.vertices), np.asarray(mesh.faces))
    video = render_video(Twin(cell), traj, toolpath, job_dir / "figures" / "dry_run.mp4",
                         speedup=speedup, width=size[0], height=size[1],
                         clearance=result.clearance, low_clearance_mm=max(5.0, 2 * required),
                         part=part)
    if video.path is None:
        progress.info(f"video skipped: {video.message}")
        return {"skipped": video.message}
    progress.info(f"video: {video.path} ({video.frames} frames, {video.render_s:.0f} s, "
                  f"{video.render_s_per_print_min:.2f} s per print minute), {video.sheet}")
    return {"path": str(video.path.relative_to(job_dir)),
            "sheet": str(video.sheet.relative_to(job_dir)) if video.sheet else "",
            "frames": video.frames, "speedup": speedup, "size_px": [video.width, video.height],
            "low_clearance_mm": max(5.0, 2 * required), "render_s": round(video.render_s, 2),
            "render_s_per_print_min": round(video.render_s_per_print_min, 3)}


def _checked_fix(job_dir: Path, toolpath: Any, cell: Any, cell_path: Path | None, why: Any,
                 fallback: str) -> str:
    """The fix of a refused job: a planning option the planner re-planned with, written into
    DIR/cell_checked.toml (the user's cell plus the option), else another bundled cell that
    plans it, else ``fallback`` with what was tried (``planner.option_retry``,
    ``planner.other_cells``)."""
    import tomli_w

    from core.configtools import read_toml
    from planner.option_retry import as_cell, retry
    from planner.other_cells import checked_fix, shown, try_cells

    found = retry(toolpath, cell, why)
    if found.option is not None:
        path = job_dir / "cell_checked.toml"
        user = read_toml(cell_path) if cell_path is not None else {}
        path.write_text(tomli_w.dumps(as_cell(user, found.option)))
        settings = ", ".join(f"{k} = {v:g}" for k, v in found.option.items())
        return (f"plan with --cell {shown(path)} (the cell you planned with, plus [planning] "
                f"{settings}; checked: the job plans ok with it)")
    fix = checked_fix(try_cells(toolpath, cell_path), fallback)
    return fix + (f"; planning options tried: {'; '.join(found.tried)}" if found.tried else "")


def _fix(result: Any) -> str:
    """What to do about a plan the cell cannot execute: the fix of its first refused
    waypoint's cause, else of its status."""
    from planner.status import FIXES, PlanStatus

    if result.cause is not None:
        return str(FIXES[result.cause])
    if result.status in (PlanStatus.ENTRY_BLOCKED, PlanStatus.EXIT_BLOCKED, PlanStatus.SWING):
        return "move the part ([placement] offset_mm, yaw_deg) or the robot base"
    return "move the part or use a cell that reaches it"
