"""`mesp preview DIR`: an interactive HTML view of the layers and toolpath, offline."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from core.errors import InputError

HELP = """\
Write DIR/preview.html: the toolpath in 3D, one line per layer, coloured by layer, width,
height, speed and (once `mesp plan` ran) the printing angle alpha and the slowdown; a slider
shows the layers up to one; the legend shows travel moves and nozzle axes on demand. The
plotting library is inside the file, so it opens in a browser without a network.
`mesp plan` writes the same file.
"""


def register(sub: Any) -> None:
    """Add the `preview` sub-command."""
    p = sub.add_parser("preview", help="interactive offline HTML view of layers and toolpath",
                       description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dir", type=Path, metavar="DIR", help="job directory with toolpath.npz")
    p.add_argument("--out", type=Path, metavar="FILE", help="output (default DIR/preview.html)")
    p.add_argument("--max-points", type=int, default=150_000, metavar="N",
                   help="waypoints drawn at most; longer jobs are thinned along each path")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Write the preview and say where."""
    from core.stages import Toolpath
    from planner.trajectory import Trajectory
    from sim.preview import write_preview

    job: Path = args.dir
    if not (job / "toolpath.npz").is_file():
        raise InputError(f"{job} has no toolpath.npz", f"run `mesp slice MODEL --out {job}` first")
    if args.max_points < 100:
        raise InputError(f"--max-points {args.max_points} is too few", "pass 100 or more")
    traj = Trajectory.load(job) if (job / "trajectory.npz").is_file() else None
    out = write_preview(Toolpath.load(job), args.out or job / "preview.html", traj,
                        args.max_points)
    print(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB)")
    return 0
