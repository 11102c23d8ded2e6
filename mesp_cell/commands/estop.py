"""`mesp estop`: stop every motion and extrusion of a running cell at once.

The stop goes through the cell's resident e-stop node (``estop_socket``) when it runs: the
command imports nothing but the standard library before the stop is published. Without it
(a cell launched without the node) the command joins the bus itself, which takes seconds.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from core.errors import InputError


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "estop", help="emergency stop: robot and extruder stop at once",
        description="Publish an e-stop on the cell bus: the robot node stops its stream "
        "(servoStop) and the extruder node stops the motor and latches the e-stop fault. The "
        "printing job becomes 'interrupted'. It then prints what stopped and when (a node that "
        "does not confirm within 2 s is an error). Nothing moves again until `mesp estop --reset`. "
        "This is a software stop; it does not replace the cell's hardware e-stop circuit.")
    p.add_argument("--reason", default="operator", help="text recorded with the stop")
    p.add_argument("--reset", action="store_true", help="clear a latched e-stop instead")
    p.add_argument("--on", metavar="CELL", default=None, help="name of the running cell")
    p.set_defaults(func=run)


def fast(argv: Sequence[str]) -> int | None:
    """`mesp estop [--reason R] [--on CELL]` through the resident e-stop node; None when it
    cannot (other options, no node listening): then the full command runs."""
    reason, cell = "operator", None
    rest = list(argv)
    while rest:
        opt = rest.pop(0)
        if opt in ("--reason", "--on") and rest:
            value = rest.pop(0)
            reason, cell = (value, cell) if opt == "--reason" else (reason, value)
        else:
            return None  # --reset, --help, a typo: the parser answers
    from mesp_cell.estop_socket import send, socket_path

    path = socket_path(cell)
    if path is None:
        return None
    try:
        answer = send(path, reason)
    except (OSError, ValueError):
        return None  # the node is gone: join the bus instead
    lines = answer.get("lines", [])
    for text in lines if isinstance(lines, list) else []:
        print(text)
    if not answer.get("confirmed"):
        print("mesp: error: the e-stop was not confirmed by every node; use the cell's "
              "hardware e-stop now", file=sys.stderr)
        return 2
    return 0


def run(args: argparse.Namespace) -> int:
    from mesp_cell.cell_client import CellClient

    client = CellClient.for_cell(args.on)
    try:
        if args.reset:
            bad = client.reset_estop()
            if bad:
                raise InputError(f"{', '.join(bad)} did not confirm the reset",
                                 "check that the cell is running (`mesp launch`)")
            print("e-stop cleared")
            return 0
        from mesp_cell.estop_check import confirm_estop

        printing = tuple(j.id for j in client.store.query(client.cell, ("printing",)))
        sent = client.estop(args.reason)
        done = confirm_estop(client.bus(), client.store, client.cell, sent, printing)
        for text in done.lines():
            print(text)
        if not done.confirmed:
            raise InputError("the e-stop was not confirmed by every node",
                             "use the cell's hardware e-stop now")
    finally:
        client.close()
    return 0
