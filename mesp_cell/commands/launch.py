"""`mesp launch FILE`: start the processes a launch description names and watch them."""

from __future__ import annotations

import argparse
import math
import signal
import sys
from pathlib import Path

from core.errors import InputError


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "launch", help="start the cell's processes from a launch file",
        description="Start every process of a launch description (launch/sim.toml: the twin "
        "and the emulated extruder; launch/cell.toml: the real UR5e and extruder), keep one log "
        "per process, restart or fail fast per process, and stop everything on Ctrl-C.")
    p.add_argument("file", help="launch TOML, or a bundled name: sim | cell")
    p.add_argument("--set", action="append", default=[], metavar="VAR=VALUE",
                   help="override a [vars] entry (repeatable), e.g. --set true_gain=1.1")
    p.add_argument("--log-dir", type=Path, help="where the per-process logs go")
    p.set_defaults(func=run)


def parse_sets(items: list[str]) -> dict[str, object]:
    """``VAR=VALUE`` strings -> a dict (numbers become numbers)."""
    out: dict[str, object] = {}
    for item in items:
        name, eq, value = item.partition("=")
        if not eq or not name:
            raise InputError(f"--set '{item}' is not VAR=VALUE", "write e.g. --set true_gain=1.1")
        try:
            out[name] = int(value)
        except ValueError:
            try:
                number = float(value)
            except ValueError:
                out[name] = value
                continue
            if not math.isfinite(number):
                raise InputError(f"--set {item} is not a finite number",
                                 f"give {name} a number, e.g. --set {name}=1.0") from None
            out[name] = number
    return out


def run(args: argparse.Namespace) -> int:
    from mesp_cell.launch_file import bundled_launch, load_launch
    from mesp_cell.launcher import Launch, LaunchFailed

    path = Path(args.file)
    if not path.is_file() and bundled_launch(args.file).is_file():
        path = bundled_launch(args.file)
    if not path.is_file():
        raise InputError(f"launch file {path} does not exist",
                         "give a path or a bundled name: sim, cell")
    spec = load_launch(path, parse_sets(args.set))

    def say(text: str) -> None:
        print(f"mesp launch: {text}", file=sys.stderr, flush=True)

    launch = Launch(spec, log_dir=args.log_dir, on_event=say)
    try:
        launch.start()
    except LaunchFailed as exc:
        raise InputError(str(exc), exc.fix) from exc
    say(f"cell '{spec.cell}' running (bus hub {spec.hub}); logs in {launch.log_dir}; "
        "Ctrl-C stops it")
    from mesp_cell.web.node import console_urls

    for url in console_urls(spec.processes):
        say(f"console: {url}")
    # Ctrl-C and SIGTERM both stop the cell cleanly. Installed explicitly: a process started
    # in the background by a non-interactive shell inherits SIGINT *ignored*, and Python then
    # never raises KeyboardInterrupt.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    code = launch.run_forever()
    say("stopped" if code == 0 else f"failed: {launch.failed}")
    return code
