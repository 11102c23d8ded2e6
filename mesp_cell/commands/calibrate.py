"""`mesp calibrate extrusion|morphology`: measure C and f at the cell, write a new profile."""

from __future__ import annotations

import argparse
import csv
import shlex
import sys
from datetime import datetime
from pathlib import Path
from typing import Any

from core.errors import InputError

EXTRUSION = """\
Guided calibration of the extrusion rate C at the cell (paper sections 3.2, 5.2).

The extruder runs at the set-point the cell prints with (the base profile's) into a tared cup,
once per run time; after each run the cup is weighed (typed in, or read from --scale). C is the
slope of net mass vs run time over the density, with its uncertainty; the intercept is the
start-up transient. Masses outside --band of what the base profile expects, or a run off the
line of the others by more than --consistency, are refused with the reason.

Writes a new, dated profile (calibrated = true) to the lab's profiles ($MESP_HOME/profiles,
see `mesp profile list`) and a plot of mass vs time; --activate makes it the cell's profile,
so the next job is sliced and printed with it. Runs already weighed by hand: --masses FILE
(CSV: seconds,mass_g), no extruder needed.
"""

MORPHOLOGY = """\
Fit the filament morphology f from measured cross-sections (paper section 3.1, Fig. 3).

TABLE.csv has a header with speed_mm_s, width_mm, height_mm and one row per filament printed at
the profile's C and measured; power laws w_f(v), h_f(v) are fitted and sampled into the new
profile's [morphology] table (the slicer's f is its inverse h_f -> v), with a plot of the fit.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "calibrate", help="extrusion-rate and filament-morphology calibration",
        description="Calibrate the extrusion rate C or the filament morphology f at the cell "
        "and write a new extrusion profile (`mesp profile`).")
    sub = p.add_subparsers(dest="what", metavar="WHAT")
    sub.required = True
    e = sub.add_parser("extrusion", help="weigh timed runs at the set-point, fit C",
                       description=EXTRUSION, formatter_class=_Formatter)
    link = e.add_mutually_exclusive_group()
    link.add_argument("--modbus", metavar="HOST:PORT", help="extruder controller (Modbus TCP)")
    link.add_argument("--serial", metavar="URL", help="extruder controller (serial line)")
    link.add_argument("--emulate", type=float, metavar="GAIN",
                      help="dry run on an emulated extruder delivering GAIN x its set-point, "
                      "weighed by an emulated scale with noise")
    link.add_argument("--masses", type=Path, metavar="FILE",
                      help="CSV of runs already weighed (seconds,mass_g): fit only")
    e.add_argument("--seconds", default="30,60,90,120", help="run times, s")
    e.add_argument("--setpoint", type=float, default=None,
                   help="mm^3/s commanded (default: the base profile's setpoint_mm3_s)")
    e.add_argument("--settle", type=float, default=2.0, help="wait after each stop, s")
    e.add_argument("--scale", metavar="URL", help="serial balance (else type each mass in)")
    e.add_argument("--density", type=float, help="g/cm^3 (default: the base profile's)")
    e.add_argument("--band", type=float, default=0.3,
                   help="a mass further than this fraction from the expected one is refused")
    e.add_argument("--consistency", type=float, default=0.05,
                   help="a run further than this fraction from the line of the others is "
                   "refused")
    e.add_argument("--countdown", type=int, default=3, help="s of countdown before each run")
    e.add_argument("--yes", action="store_true",
                   help="no prompts (scripted: masses from --scale or --emulate)")
    e.add_argument("--time-scale", type=float, default=1.0,
                   help="--emulate only: the emulated extruder runs this many times faster")
    e.add_argument("--seed", type=int, default=None, help="--emulate only: noise seed")
    _profile_args(e)
    e.set_defaults(func=extrusion)
    m = sub.add_parser("morphology", help="fit filament width/height vs speed from a table",
                       description=MORPHOLOGY, formatter_class=_Formatter)
    m.add_argument("table", type=Path, help="CSV of measured filaments")
    m.add_argument("--points", type=int, default=13, help="rows of the written table")
    _profile_args(m)
    m.set_defaults(func=morphology)


class _Formatter(argparse.RawDescriptionHelpFormatter):
    """Description kept as written; each option's default shown where it has one."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if action.default in (None, False, argparse.SUPPRESS) or "default" in text:
            return text
        return f"{text} (default: %(default)s)"


def _profile_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--on", metavar="CELL", default=None,
                   help="the cell (default: the only one running, else 'sim')")
    p.add_argument("--profile", default=None, metavar="NAME|PATH",
                   help="profile to start from (default: the cell's active profile)")
    p.add_argument("--name", default=None,
                   help="name of the new profile (default: <material>-<today>)")
    p.add_argument("--out", type=Path, default=None,
                   help="write the profile here (default: $MESP_HOME/profiles/<name>.toml)")
    p.add_argument("--activate", action="store_true",
                   help="make the new profile the cell's active one")


def _base(args: argparse.Namespace) -> tuple[Any, str, datetime, str]:
    """(base profile, cell, now, name of the new profile)."""
    from mesp_cell import profiles
    from mesp_cell.profile_write import default_name

    cell = args.on or profiles.default_cell()
    base = profiles.find(args.profile) if args.profile else profiles.active(cell)
    when = datetime.now().astimezone()
    name = profiles.check_name(args.name or default_name(base, when))
    return base, cell, when, name


def _finish(args: argparse.Namespace, text: str, name: str, cell: str) -> Path:
    """Save the profile (library or --out), activate it if asked; the path written."""
    from core.artifacts import atomic_write_bytes
    from mesp_cell import profiles

    if args.out is not None:
        atomic_write_bytes(args.out, text.encode())
        path = args.out
    else:
        path = profiles.save(text, name)
    print(f"wrote profile {path}")
    if args.activate:
        active = profiles.activate(str(path), cell)
        print(f"cell '{cell}' now prints with {profiles.describe(active)}")
    else:
        print(f"to print with it: mesp profile activate {name if args.out is None else path}"
              f" --on {cell}")
    return path


def _list(text: str, what: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError as exc:
        raise InputError(f"{what} '{text}' is not a list of numbers",
                         f"write e.g. {what} 30,60,90,120") from exc
    if not values or min(values) <= 0:
        raise InputError(f"{what} must be positive", f"write e.g. {what} 30,60,90,120")
    return values


def _read_masses(path: Path) -> tuple[list[float], list[float]]:
    if not path.is_file():
        raise InputError(f"masses file {path} does not exist", "check the path")
    with open(path, newline="") as f:
        rows = list(csv.DictReader(r for r in f if r.strip() and not r.startswith("#")))
    try:
        return [float(r["seconds"]) for r in rows], [float(r["mass_g"]) for r in rows]
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{path}: needs a header seconds,mass_g and numbers ({exc})",
                         "write one line per run, e.g. 60,0.4218") from exc


def extrusion(args: argparse.Namespace) -> int:
    from mesp_cell.calibration import check_consistency, check_mass, check_runs, fit_rate
    from mesp_cell.calibration_plot import plot_rate
    from mesp_cell.profile_write import calibrated_text

    base, cell, when, name = _base(args)
    density = args.density if args.density is not None else _density(base)
    setpoint = args.setpoint if args.setpoint is not None else base.setpoint_mm3_s
    if not setpoint > 0 or not 0 < args.band < 1 or not 0 < args.consistency < 1:
        raise InputError("--setpoint must be positive, --band and --consistency in (0, 1)",
                         "see `mesp calibrate extrusion --help`")
    expected_rate = base.rate_mm3_s * setpoint / base.setpoint_mm3_s  # the base's C per set-point

    def check(i: int, seconds: float, grams: float) -> str:
        return check_mass(i, seconds, grams, expected_rate, density, args.band)

    print(f"calibrating C of '{base.name}' (C {base.rate_mm3_s:g} mm^3/s at set-point "
          f"{base.setpoint_mm3_s:g}) at set-point {setpoint:g} mm^3/s, density {density:g} g/cm^3")
    if args.masses is not None:
        seconds, masses = _read_masses(args.masses)
        for i, (t, m) in enumerate(zip(seconds, masses, strict=True)):
            why = check(i, t, m)
            if why:
                raise InputError(why, f"fix {args.masses} or redo that run")
    else:
        seconds = _list(args.seconds, "--seconds")
        check_runs(seconds)  # before the extruder runs
        masses = _run(args, seconds, setpoint, density, expected_rate, check)
    why = check_consistency(seconds, masses, args.consistency)
    if why:
        raise InputError(why, "redo that run (a spill, a knocked cup, a missed tare?)")
    fit = fit_rate(seconds, masses, density, setpoint)
    print(f"C = {fit.C:.4f} mm^3/s +- {fit.u_C:.4f} (standard, {fit.relative_uncertainty:.2%}; "
          f"95 %: +- {fit.expanded(0.95):.4f}) at set-point {setpoint:g} mm^3/s; start-up "
          f"volume {fit.v0:+.2f} mm^3; was {base.rate_mm3_s:g}")
    command = "mesp calibrate " + " ".join(shlex.quote(a) for a in sys.argv[2:])
    text = calibrated_text(base, name, when, rate=fit, command=command)
    path = _finish(args, text, name, cell)
    plot = plot_rate(fit, path.with_name(f"{path.stem}-extrusion.png"), name)
    print(f"plot {plot}")
    return 0


def _density(base: Any) -> float:
    import tomllib

    value = tomllib.loads(base.text).get("density_g_cm3")
    if value is None:
        raise InputError(f"profile '{base.name}' has no density_g_cm3", "give --density G_CM3")
    return float(value)


def _run(args: argparse.Namespace, seconds: list[float], setpoint: float, density: float,
         expected_rate: float, check: Any) -> list[float]:
    """The runs on the extruder, guided; the net masses."""
    from mesp_cell.calibration import run_extrusion
    from mesp_cell.calibration_guide import Guide
    from mesp_cell.drivers.extruder_base import ExtruderDriver, ExtruderLinkError
    from mesp_cell.scale import Scale, SerialScale

    emulator: Any = None
    driver: ExtruderDriver
    scale: Scale | None = None
    time_scale = 1.0
    if args.modbus:
        from mesp_cell.drivers.extruder_modbus import ModbusExtruder

        host, _, port = args.modbus.rpartition(":")
        if not host or not port.isdigit():
            raise InputError(f"--modbus '{args.modbus}' is not HOST:PORT", "e.g. 10.0.0.5:502")
        driver = ModbusExtruder(host, int(port))
    elif args.serial:
        from mesp_cell.drivers.extruder_serial import SerialExtruder

        driver = SerialExtruder(args.serial)
    elif args.emulate is not None:
        from mesp_cell.drivers.extruder_emulator import EmulatorThread
        from mesp_cell.drivers.extruder_modbus import ModbusExtruder
        from mesp_cell.drivers.extruder_plant import PlantParams
        from mesp_cell.drivers.scale_emulator import EmulatedScale

        if not args.emulate > 0 or not args.time_scale > 0:
            raise InputError("--emulate GAIN and --time-scale must be positive", "e.g. 1.05")
        time_scale = args.time_scale
        emulator = EmulatorThread(PlantParams(gain=args.emulate, time_scale=time_scale,
                                              startup_tau_s=0.5)).__enter__()
        driver = ModbusExtruder("127.0.0.1", emulator.port)
        scale = EmulatedScale(emulator.plant, density, seed=args.seed)
    else:
        raise InputError("no extruder given",
                         "use --modbus HOST:PORT, --serial URL, --emulate GAIN or --masses FILE")
    if args.scale:
        scale = SerialScale(args.scale)
    try:
        guide = Guide(len(seconds), setpoint, check,
                      lambda i, t: expected_rate * t * density / 1000.0, scale, args.yes,
                      args.countdown)
        return run_extrusion(driver, setpoint, seconds, guide.before_run, guide.during_run,
                             guide.weigh, args.settle, time_scale)
    except ExtruderLinkError as exc:
        raise InputError(str(exc), "check the extruder's address and cable") from exc
    finally:
        if scale is not None:
            scale.close()
        if emulator is not None:
            emulator.__exit__(None, None, None)


def morphology(args: argparse.Namespace) -> int:
    from mesp_cell.calibration_plot import plot_morphology
    from mesp_cell.morphology_fit import fit_morphology, read_morphology_csv
    from mesp_cell.profile_write import calibrated_text

    base, cell, when, name = _base(args)
    v, w, h = read_morphology_csv(args.table)
    fit = fit_morphology(v, w, h, args.points)
    print(f"w_f = {fit.a_w:.4f} v^{fit.b_w:.4f} mm (R^2 {fit.r2_w:.4f}); "
          f"h_f = {fit.a_h:.4f} v^{fit.b_h:.4f} mm (R^2 {fit.r2_h:.4f}); "
          f"{fit.samples} filaments, v in [{v.min():g}, {v.max():g}] mm/s")
    command = "mesp calibrate " + " ".join(shlex.quote(a) for a in sys.argv[2:])
    text = calibrated_text(base, name, when, morphology=fit, command=command)
    path = _finish(args, text, name, cell)
    plot = plot_morphology(fit, v, w, h, path.with_name(f"{path.stem}-morphology.png"), name)
    print(f"plot {plot}")
    return 0
