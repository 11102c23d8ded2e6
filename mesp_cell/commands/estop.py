"""`mesp estop`: stop every motion and extrusion of a running cell at once.

The stop goes through the cell's resident e-stop node when it runs: ``mesp_cell.cli`` hands
`mesp estop` to ``estop_socket.fast_estop`` before it imports anything else, so the stop is
published after the interpreter's start-up and a Unix-socket write. Without the node (a cell
launched without it) this command joins the bus itself, which takes seconds.
"""

from __future__ import annotations

import argparse

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
