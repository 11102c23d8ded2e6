"""`mesp profile list|show|activate`: the lab's extrusion profiles and the cell's active one."""

from __future__ import annotations

import argparse
import tomllib

from core.errors import InputError


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "profile", help="list, show or activate extrusion profiles",
        description="Extrusion profiles (C at its set-point, density, beta, morphology table) "
        "are files a lab keeps in $MESP_HOME/profiles (written by `mesp calibrate`) beside the "
        "bundled ones. Each cell prints with its active profile: jobs are sliced with it and "
        "a job sliced with another is refused before it moves.")
    p.add_argument("--on", metavar="CELL", default=None,
                   help="the cell (default: the only one running, else 'sim')")
    sub = p.add_subparsers(dest="action", metavar="ACTION")
    sub.required = True
    sub.add_parser("list", help="every profile, the active one marked *").set_defaults(
        func=list_profiles)
    s = sub.add_parser("show", help="one profile's values and calibration record")
    s.add_argument("profile", nargs="?", default=None,
                   help="name or path (default: the cell's active profile)")
    s.set_defaults(func=show)
    a = sub.add_parser("activate", help="make a profile the cell's active one")
    a.add_argument("profile", help="name (`mesp profile list`) or path of a profile .toml")
    a.set_defaults(func=activate)


def _cell(args: argparse.Namespace) -> str:
    from mesp_cell.profiles import default_cell

    return str(args.on or default_cell())


def list_profiles(args: argparse.Namespace) -> int:
    from mesp_cell import profiles

    cell = _cell(args)
    current = profiles.active(cell)
    print(f"cell '{cell}' prints with {profiles.describe(current)}")
    for entry in profiles.entries():
        try:
            prof = entry.load()
        except InputError as exc:
            print(f"  ! {entry.name:<28} unreadable: {exc.one_line()}")
            continue
        mark = "*" if prof.sha256 == current.sha256 else " "
        where = "bundled" if entry.bundled else str(entry.path)
        print(f"  {mark} {entry.name:<28} C {prof.rate_mm3_s:7.4g} mm^3/s at "
              f"{prof.setpoint_mm3_s:<6g} {'calibrated' if prof.calibrated else 'model':<10} "
              f"{prof.sha256[:12]}  {where}")
    return 0


def show(args: argparse.Namespace) -> int:
    from mesp_cell import profiles

    cell = _cell(args)
    prof = profiles.find(args.profile) if args.profile else profiles.active(cell)
    active = profiles.active(cell).sha256 == prof.sha256
    data = tomllib.loads(prof.text)
    print(profiles.describe(prof) + (f" (active on cell '{cell}')" if active else ""))
    print(f"  material   {data.get('material', '-')}")
    print(f"  density    {data.get('density_g_cm3', '-')} g/cm^3, beta {prof.beta:g}, "
          f"layer heights {prof.layer_height_range[0]:.3g}-{prof.layer_height_range[1]:.3g} mm")
    print(f"  morphology {len(prof.speed)} speeds {prof.speed[0]:g}-{prof.speed[-1]:g} mm/s")
    for what, rec in data.get("calibration", {}).items():
        detail = ", ".join(f"{k} {v}" for k, v in rec.items() if k != "date")
        print(f"  calibrated {what} {rec.get('date', '')}: {detail}")
    if data.get("provenance"):
        print(f"  provenance {data['provenance']}")
    return 0


def activate(args: argparse.Namespace) -> int:
    from mesp_cell import profiles

    cell = _cell(args)
    prof = profiles.activate(args.profile, cell)
    print(f"cell '{cell}' now prints with {profiles.describe(prof)}")
    print("jobs sliced with another profile are refused until re-submitted")
    return 0
