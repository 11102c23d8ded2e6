"""`mesp export DIR --format printpoints|urscript|csv`: the job for tools outside MESP Cell."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from core.errors import InputError

HELP = """\
Write the job in a format other tools read (limits of each in docs/exports.md):

  printpoints  compas_slicer's printpoints JSON (flat {"0": point, ...}, PrintPoint.to_data
               fields; model frame, mm, mm/s), from toolpath.npz
  urscript     a URScript program replaying trajectory.npz with servoj on a UR controller,
               the extruder run by a standard digital output and its rate set on an analog
               output (needs `mesp plan` first; refused for a plan the cell would refuse)
  csv          every toolpath waypoint as one row (model frame, mm, mm/s), with a header

Files go to DIR/export/ unless --out names one.
"""

NAMES = {"printpoints": "printpoints.json", "urscript": "print.script", "csv": "waypoints.csv"}


def register(sub: Any) -> None:
    """Add the `export` sub-command."""
    p = sub.add_parser("export", help="toolpath/trajectory -> printpoints JSON, URScript, CSV",
                       description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dir", type=Path, metavar="DIR", help="job directory")
    p.add_argument("--format", required=True, choices=sorted(NAMES), help="what to write")
    p.add_argument("--out", type=Path, metavar="FILE", help="output file (default DIR/export/)")
    p.add_argument("--run-output", type=int, default=0, metavar="N",
                   help="urscript: standard digital output that runs the extruder (default 0)")
    p.add_argument("--rate-output", type=int, default=0, metavar="N",
                   help="urscript: standard analog output of the rate set-point (default 0)")
    p.add_argument("--rate-full-scale", type=float, default=20.0, metavar="MM3S",
                   help="urscript: extruder rate at full-scale analog signal (default 20)")
    p.add_argument("--max-step", type=float, default=0.1, metavar="S",
                   help="urscript: longest servoj step, s (default 0.1)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Write the requested export and print where it went."""
    from core.artifacts import atomic_write_bytes

    job: Path = args.dir
    if not (job / "toolpath.npz").is_file():
        raise InputError(f"{job} has no toolpath.npz", f"run `mesp slice MODEL --out {job}` first")
    out: Path = args.out or job / "export" / NAMES[args.format]
    text = {"printpoints": _printpoints, "urscript": _urscript, "csv": _csv}[args.format](
        job, args)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out, text.encode())
    print(f"wrote {out} ({len(text) / 1e6:.2f} MB)")
    return 0


def _printpoints(job: Path, args: argparse.Namespace) -> str:
    from core.stages import Toolpath
    from slicer.toolpath.printpoints import printpoints_json

    return printpoints_json(Toolpath.load(job))


def _csv(job: Path, args: argparse.Namespace) -> str:
    from core.stages import Toolpath
    from slicer.toolpath.printpoints import waypoints_csv

    return waypoints_csv(Toolpath.load(job))


def _urscript(job: Path, args: argparse.Namespace) -> str:
    from core.report import read_report
    from planner.plan_summary import PlanSummary
    from planner.status import PlanStatus
    from planner.trajectory import Trajectory
    from sim.urscript import ExtruderIO, urscript
    from slicer.extrusion import load_job_profile

    if not (job / "trajectory.npz").is_file():
        raise InputError(f"{job} has no trajectory.npz", f"run `mesp plan {job}` first")
    report = read_report(job)
    status = PlanSummary.of(report.get("plan", {})).status
    if status != PlanStatus.OK:
        raise InputError(f"the plan in {job} cannot be executed ({status})",
                         f"fix the plan (see plan in {job / 'report.json'}) and re-run mesp plan")
    if args.max_step < 0.002:
        raise InputError(f"--max-step {args.max_step} s is below the 2 ms controller period",
                         "pass --max-step 0.002 or more")
    setpoint = load_job_profile(job).setpoint_mm3_s  # the profile owns C and its set-point
    io = ExtruderIO(setpoint, args.run_output, args.rate_output, args.rate_full_scale)
    return urscript(Trajectory.load(job), io, max_step_s=args.max_step)
