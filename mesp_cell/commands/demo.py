"""`mesp demo`: a whole print job on a bundled example, through the real processes.

Starts the simulated cell (launch/sim.toml: every node as its own process on the zenoh bus,
the MuJoCo twin of the UR5e and the emulated Modbus extruder), submits a bundled example,
follows it through slicing, planning and printing (faster than real time), then runs the
virtual print (`mesp inspect`) on the result and prints a summary. Everything lands in
``--out`` (default ``out/demo``): the cell's state, logs and the job directory. An example
planned for another cell than the bundled one (``examples/cells.toml``: the membrane, a
shallow tray) gets the twin started with that cell and the job planned for it.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import tomllib
from pathlib import Path
from typing import Any, NamedTuple

from core.errors import InputError
from core.status import JobState

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
DEFAULT_EXAMPLE = "hemisphere"


def register(sub: Any) -> None:
    """Add the `demo` sub-command."""
    p = sub.add_parser(
        "demo",
        help="print a bundled example on the MuJoCo twin through the real processes",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--example",
        default=DEFAULT_EXAMPLE,
        help=f"bundled example name in examples/ (default {DEFAULT_EXAMPLE})",
    )
    p.add_argument("--out", type=Path, default=Path("out/demo"), help="state and job directory")
    p.add_argument(
        "--time-scale",
        type=float,
        default=40.0,
        help="the twin runs this many times faster than real time (default 40)",
    )
    p.add_argument("--no-inspect", action="store_true", help="skip the virtual print")
    p.add_argument("--console", action="store_true",
                   help="leave the tank-ready confirmation to the operator in the web console "
                   "and keep the cell and its console running after the job until Ctrl-C")
    p.add_argument("--timeout", type=float, default=900.0,
                   help="give up after this many s without progress (default 900)")
    p.set_defaults(func=run)


class Example(NamedTuple):
    """A bundled example: model file, job TOML (None: the defaults) and the cell TOML it is
    planned for (None: the bundled cell; ``examples/cells.toml`` names the others)."""

    model: Path
    job: Path | None
    cell: Path | None


def _example(name: str) -> Example:
    models = sorted(p for p in EXAMPLES.glob(f"{name}.*") if p.suffix in {".stl", ".ply", ".obj"})
    if not models:
        known = sorted({p.stem for p in EXAMPLES.glob("*.stl")})
        raise InputError(f"no bundled example '{name}'", f"choose one of {', '.join(known)}")
    job = EXAMPLES / f"{name}.toml"
    cells = EXAMPLES / "cells.toml"
    cell_name = tomllib.loads(cells.read_text()).get(name) if cells.is_file() else None
    cell = EXAMPLES.parent / cell_name if cell_name else None
    return Example(models[0], job if job.is_file() else None, cell)


def run(args: argparse.Namespace) -> int:
    """Run the demo; returns 0 when the job printed completely."""
    from mesp_cell.launcher import LaunchFailed, start_cell

    if args.time_scale <= 0:
        raise InputError(f"--time-scale {args.time_scale}", "give a positive factor, e.g. 40")
    model, job_file, cell_file = _example(args.example)
    home = args.out.resolve()
    home.mkdir(parents=True, exist_ok=True)
    os.environ["MESP_HOME"] = str(home)  # the cell's job store, logs and job dirs stay here
    say = _Printer()
    say.line(f"mesp demo: {model.name} on the simulated cell (state in {home})")
    t0 = time.monotonic()
    try:
        # the twin models the cell the job is planned for
        overrides: dict[str, Any] = {"time_scale": args.time_scale}
        if cell_file is not None:
            overrides["cell_file"] = str(cell_file)
            say.line(f"cell: {cell_file.relative_to(EXAMPLES.parent)} (examples/cells.toml)")
        cell = start_cell(overrides=overrides, on_event=say.event)
    except LaunchFailed as exc:
        raise InputError(str(exc), exc.fix) from exc
    with cell:
        say.line(f"cell up in {time.monotonic() - t0:.1f} s: {', '.join(sorted(cell.alive))}")
        from mesp_cell.web.node import console_urls

        urls = console_urls(cell.spec.processes)
        for url in urls:
            say.line(f"console: {url}")
        client = cell.client()
        try:
            job = client.submit(model, job_file=job_file, cell_file=cell_file)
            say.line(f"submitted job {job.id}")
            if args.console and urls:
                say.line(f"job {job.id} waits for the tank-ready confirmation: press 'Tank "
                         f"ready' in the console ({urls[0]})")
                client.wait(job.id, timeout=1e9, until=frozenset(
                    {JobState.PRINTING, JobState.PAUSED, JobState.INTERRUPTED, JobState.DONE,
                     JobState.FAILED, JobState.ABORTED}))
            else:
                client.confirm_ready(job.id, timeout=args.timeout, who="mesp demo")
                say.line("tank confirmed ready (the twin's tank is virtual)")
            try:
                done = client.wait(job.id, on_progress=say.progress, timeout=args.timeout,
                                   idle=True)
            except TimeoutError as exc:
                say.end_progress()
                raise InputError(str(exc), f"give it longer (--timeout; cell logs in "
                                 f"{home / 'logs'})") from exc
            if args.console and urls:
                say.end_progress()
                say.line(f"job {done.id} {done.state}; the console stays open at {urls[0]}: "
                         "Ctrl-C stops the cell")
                _hold(cell)
        finally:
            client.close()
    say.end_progress()
    elapsed = time.monotonic() - t0
    if done.state != JobState.DONE:
        print(f"mesp demo: job {done.id} ended {done.state}: {done.reason}", file=sys.stderr)
        print(f"logs: {home / 'logs'}", file=sys.stderr)
        return 1
    job_dir = Path(done.dir)
    say.line(
        f"printed {done.id}: {done.layers} layers, {done.waypoints} waypoints, "
        f"{done.volume:.0f} mm^3 extruded{_against_toolpath(job_dir, done.volume)}, "
        f"in {elapsed:.0f} s wall time"
    )
    if not args.no_inspect:
        _inspect(job_dir)
    _summary(job_dir, say.printing_s(), args.time_scale)
    return 0


def _hold(cell: Any) -> None:
    """Keep the cell (and its console) running until Ctrl-C (or SIGTERM) or a critical
    failure."""
    import signal

    # installed explicitly: a process started in the background by a non-interactive shell
    # inherits SIGINT ignored
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        while not cell.failed:
            time.sleep(0.5)
    except KeyboardInterrupt:
        print(file=sys.stderr)


#: The extruded volume may differ from the toolpath's by the lead and the priming purge; beyond
#: this the print was not what the toolpath asked for.
VOLUME_TOLERANCE = 0.02


def _against_toolpath(job_dir: Path, extruded: float) -> str:
    """`` (+0.6% of the toolpath's 16692)``, with a warning line where it is off by more than
    ``VOLUME_TOLERANCE``."""
    from core.report import read_report

    deposited = float(read_report(job_dir).get("toolpath", {}).get("deposited_volume_mm3", 0.0))
    if deposited <= 0:
        return ""
    off = extruded / deposited - 1.0
    if abs(off) > VOLUME_TOLERANCE:
        print(f"mesp demo: warning: the extruder delivered {100 * off:+.1f}% of the toolpath's "
              f"volume; see the extruder and robot logs", file=sys.stderr)
    return f" ({100 * off:+.1f}% of the toolpath's {deposited:.0f})"


def _inspect(job_dir: Path) -> None:
    from mesp_cell.cli import build_parser

    argv = ["inspect", str(job_dir), "--quiet"]
    if (job_dir / "trajectory.npz").is_file():
        argv.append("--as-planned")  # also the print at the speeds the arm will move at
    inspect_args = build_parser().parse_args(argv)
    inspect_args.func(inspect_args)


def _summary(job_dir: Path, printing_s: float = 0.0, time_scale: float = 0.0) -> None:
    """The job's numbers; ``printing_s`` (wall s spent printing) gives the pace the twin kept
    against the ``time_scale`` asked."""
    from core.report import read_report
    from planner.plan_summary import PlanSummary

    report = read_report(job_dir)
    rows = []
    model = report.get("model", {})
    rows.append(("model volume", f"{model.get('volume_mm3', float('nan')):.0f} mm^3"))
    mesh = report.get("mesh", {})
    rows.append(("tet mesh", f"{mesh.get('tets', 0)} tets"))
    slicing = report.get("slicing", {})
    height = slicing.get("height_mm", {})
    rows.append(
        (
            "layers",
            f"{slicing.get('layers')} (H mean {height.get('mean', 0):.3f} mm, "
            f"std {height.get('std', 0):.4f} mm; initial std "
            f"{slicing.get('height_std_initial_mm', 0):.4f} mm)",
        )
    )
    tp = report.get("toolpath", {})
    rows.append(
        (
            "toolpath",
            f"{tp.get('waypoints')} waypoints, {tp.get('length_mm', 0) / 1000:.1f} m, "
            f"volume error {100 * tp.get('volume_error', float('nan')):+.2f}%",
        )
    )
    plan = report.get("plan", {})
    if plan:
        duration = PlanSummary.of(plan).duration_s
        text = f"{duration:.0f} s of printing"
        if printing_s > 0 and time_scale > 0 and duration > 0:
            # the twin pauses the cell's clock when it cannot keep the pace asked for
            text += (f", printed in {printing_s:.0f} s on the twin: {duration / printing_s:.0f}x "
                     f"(asked {time_scale:g}x)")
        rows.append(("trajectory", text))
    inspect = report.get("inspect", {})
    if inspect:
        surf = inspect.get("surface_error_mm", {})
        rows.append(
            (
                "virtual print",
                f"infill {100 * inspect.get('infill_ratio', 0):.2f}% (interior "
                f"{100 * inspect.get('interior_infill_ratio', 0):.2f}%), pores "
                f"{100 * inspect.get('pore_ratio', 0):.2f}%, surface error mean "
                f"{surf.get('mean', float('nan')):.3f} mm",
            )
        )
    planned = inspect.get("as_planned", {})
    if planned:
        rows.append(
            (
                "as planned",
                f"{100 * planned.get('slowed_length_fraction', 0):.1f}% of the path slowed, "
                f"{planned.get('extra_ink_mm3', 0):.0f} mm^3 more ink, surface error mean "
                f"{planned.get('surface_error_mm', {}).get('mean', float('nan')):.3f} mm",
            )
        )
    width = max(len(k) for k, _ in rows)
    print()
    for key, value in rows:
        print(f"  {key:<{width}}  {value}")
    print(f"\n  artifacts, report.json and figures: {job_dir}")


class _Printer:
    """Operator-facing lines, and one live progress line while printing."""

    def __init__(self) -> None:
        self.live = sys.stdout.isatty()
        self._last = ""
        self._last_t = 0.0
        self._print_start: float | None = None  # monotonic s of the first printing progress
        self._print_end = 0.0  # ... and of the last (printing or done)

    def printing_s(self) -> float:
        """Wall seconds between the first and the last progress of the printing state."""
        return 0.0 if self._print_start is None else self._print_end - self._print_start

    def line(self, text: str) -> None:
        self.end_progress()
        print(text, flush=True)

    def event(self, text: str) -> None:
        if "fail" in text or "exit" in text or "restart" in text:
            self.line(f"  [cell] {text}")

    def progress(self, job: Any) -> None:
        text = f"  {job.state:<9} layer {job.layer + 1}/{job.layers}  {job.percent:5.1f}%"
        if job.state == JobState.PRINTING and job.eta_s > 0:
            from mesp_cell.commands.job import hmm

            text += f"  ETA {hmm(job.eta_s)}"
        text += f"  {job.volume:8.0f} mm^3"
        now = time.monotonic()
        if job.state in (JobState.PRINTING, JobState.DONE):
            if self._print_start is None:
                self._print_start = now
            self._print_end = now
        if self.live:
            print("\r" + text + "\x1b[K", end="", flush=True)
            self._last = text
        elif job.state != self._last or now - self._last_t > 10.0:
            print(text, flush=True)
            self._last, self._last_t = job.state, now

    def end_progress(self) -> None:
        if self.live and self._last:
            print(flush=True)
            self._last = ""
