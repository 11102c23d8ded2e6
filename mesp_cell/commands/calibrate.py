"""`mesp calibrate extrusion|morphology`: measure C and f, write the profile the slicer reads."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from slicer.errors import InputError


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "calibrate", help="extrusion-rate and filament-morphology calibration",
        description="Calibrate the extrusion rate C or the filament morphology f and write an "
        "extrusion profile (the format of slicer/profiles/ecoflex-0030.toml) that "
        "`mesp slice` reads through the job's [extrusion] profile.")
    sub = p.add_subparsers(dest="what", metavar="WHAT")
    sub.required = True
    e = sub.add_parser(
        "extrusion", help="run the extruder at set-points, weigh, fit rate vs set-point",
        description="Runs the extruder at each set-point for --seconds into a cup, then asks "
        "for the cup's mass (or reads --scale). True volume = mass / density; the "
        "controller's totaliser gives the nominal volume of the same run; the true rate is "
        "fitted against the set-point and C is the fitted rate at --operating-setpoint.")
    link = e.add_mutually_exclusive_group()
    link.add_argument("--modbus", metavar="HOST:PORT", help="extruder controller (Modbus TCP)")
    link.add_argument("--serial", metavar="URL", help="extruder controller (serial line)")
    link.add_argument("--emulate", type=float, metavar="GAIN",
                      help="use an emulated extruder whose true/nominal rate is GAIN (dry run)")
    e.add_argument("--setpoints", default="4,6.57,9",
                   help="comma-separated set-points, mm^3/s (default 4,6.57,9)")
    e.add_argument("--seconds", type=float, default=60.0, help="run time per set-point, s")
    e.add_argument("--settle", type=float, default=2.0, help="wait after each stop, s")
    e.add_argument("--scale", metavar="URL", help="serial balance (else type each mass in)")
    e.add_argument("--density", type=float, help="g/cm^3 (default: from the profile)")
    e.add_argument("--operating-setpoint", type=float, default=6.57,
                   help="set-point the cell prints at, mm^3/s (default 6.57)")
    _profile_args(e)
    e.set_defaults(func=extrusion)
    m = sub.add_parser(
        "morphology", help="fit filament width/height vs speed from a measured table",
        description="TABLE.csv has a header with speed_mm_s, width_mm, height_mm and one row "
        "per measured filament cross-section; power laws w_f(v), h_f(v) are fitted and sampled "
        "into the profile's [morphology] table (the slicer's f is its inverse h_f -> v).")
    m.add_argument("table", type=Path, help="CSV of measured filaments")
    m.add_argument("--points", type=int, default=13, help="rows of the written table")
    _profile_args(m)
    m.set_defaults(func=morphology)


def _profile_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--profile", default=None,
                   help="profile to start from: bundled name or .toml (default: --out if it "
                   "exists, else ecoflex-0030)")
    p.add_argument("--out", type=Path, default=None,
                   help="profile to write (default: <name>-calibrated.toml here)")


def _base(args: argparse.Namespace) -> tuple[dict[str, Any], Path]:
    from mesp_cell.calibration import base_profile

    if args.profile is None and args.out is not None and args.out.is_file():
        data = base_profile(args.out)
    else:
        data = base_profile(args.profile or "ecoflex-0030")
    out = args.out or Path(f"{data.get('name', 'profile')}-calibrated.toml")
    return data, out


def _parse_setpoints(text: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError as exc:
        raise InputError(f"--setpoints '{text}' is not a list of numbers",
                         "write e.g. --setpoints 4,6.57,9") from exc
    if not values or min(values) <= 0:
        raise InputError("set-points must be positive", "write e.g. --setpoints 4,6.57,9")
    return values


def _ask_mass(i: int, setpoint: float) -> float:
    while True:
        text = input(f"  mass of run {i + 1} at {setpoint:g} mm^3/s, g: ").strip()
        try:
            value = float(text)
        except ValueError:
            print("  a number in grams, please", file=sys.stderr)
            continue
        if value > 0:
            return value
        print("  the mass must be positive", file=sys.stderr)


def extrusion(args: argparse.Namespace) -> int:
    from mesp_cell.calibration import SerialScale, profile_density, run_extrusion, write_profile
    from mesp_cell.console import ConsoleProgress
    from mesp_cell.drivers.extruder_base import ExtruderDriver, ExtruderLinkError

    data, out = _base(args)
    density = profile_density(data, args.density)
    setpoints = _parse_setpoints(args.setpoints)
    emulator = None
    driver: ExtruderDriver
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

        emulator = EmulatorThread(PlantParams(gain=args.emulate)).__enter__()
        driver = ModbusExtruder("127.0.0.1", emulator.port)
    else:
        raise InputError("no extruder given", "use --modbus HOST:PORT, --serial URL or --emulate")
    scale = SerialScale(args.scale) if args.scale else None
    if scale is not None:
        weigh = lambda i, sp: scale.grams()  # noqa: E731
    elif emulator is not None:
        plant = emulator.plant
        marks = [plant.true_volume]

        def weigh(i: int, sp: float) -> float:  # the emulator's hidden truth, as a scale
            grams = (plant.true_volume - marks[-1]) * density / 1000.0
            marks.append(plant.true_volume)
            print(f"  emulated scale: {grams:.4f} g")
            return grams
    else:
        weigh = _ask_mass
    try:
        fit = run_extrusion(driver, setpoints, args.seconds, weigh, density,
                            args.operating_setpoint, args.settle, ConsoleProgress())
    except ExtruderLinkError as exc:
        raise InputError(str(exc), "check the extruder's address and cable") from exc
    finally:
        if scale is not None:
            scale.close()
        if emulator is not None:
            emulator.__exit__(None, None, None)
    for sp, r in zip(fit.setpoints, fit.true_rate, strict=True):
        print(f"  set-point {sp:7.3f} mm^3/s -> true rate {r:7.3f} mm^3/s")
    print(f"rate = {fit.slope:.4f} x set-point + {fit.intercept:.4f} mm^3/s (R^2 {fit.r2:.4f}); "
          f"C = {fit.C:.3f} mm^3/s at {fit.operating_setpoint:g}; for C = "
          f"{args.operating_setpoint:g} command {fit.setpoint_for(args.operating_setpoint):.3f}")
    print(f"wrote {write_profile(data, out, rate=fit)}")
    return 0


def morphology(args: argparse.Namespace) -> int:
    from mesp_cell.calibration import fit_morphology, read_morphology_csv, write_profile

    data, out = _base(args)
    v, w, h = read_morphology_csv(args.table)
    fit = fit_morphology(v, w, h, args.points)
    print(f"w_f = {fit.a_w:.4f} v^{fit.b_w:.4f} mm (R^2 {fit.r2_w:.4f}); "
          f"h_f = {fit.a_h:.4f} v^{fit.b_h:.4f} mm (R^2 {fit.r2_h:.4f}); "
          f"{fit.samples} filaments, v in [{v.min():g}, {v.max():g}] mm/s")
    print(f"wrote {write_profile(data, out, morphology=fit)}")
    return 0
