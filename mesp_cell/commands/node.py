"""`mesp node list`: the nodes of a running cell, like ``ros2 node list``."""

from __future__ import annotations

import argparse
from typing import Any


def register(sub: Any) -> None:
    """Add the `node` sub-command."""
    p = sub.add_parser("node", help="nodes of a running cell (name, state, pid, heartbeat)",
                       description="Look at the nodes of a running cell over its bus.")
    p.add_argument("--on", metavar="CELL", default=None,
                   help="name of the running cell (default: the only one running, else 'sim')")
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    actions.required = True
    ls = actions.add_parser("list", help="every node: liveliness, lifecycle state, pid and "
                            "the age of its last heartbeat")
    ls.add_argument("--listen", type=float, default=1.5, metavar="S",
                    help="how long to listen for heartbeats (default 1.5 s; they come at 2 Hz)")
    ls.set_defaults(func=list_nodes)


def list_nodes(args: argparse.Namespace) -> int:
    """Print one table row per node."""
    from rich.console import Console
    from rich.table import Table

    from mesp_cell.cell_client import CellClient
    from mesp_cell.introspect import node_list

    client = CellClient.for_cell(args.on)
    try:
        nodes = node_list(client.bus(), args.listen)
    finally:
        client.close()
    table = Table(title=f"nodes of cell '{client.cell}'", title_justify="left")
    for col in ("node", "alive", "state", "pid", "heartbeat age (s)"):
        table.add_column(col, justify="right" if col in ("pid", "heartbeat age (s)") else "left")
    for n in nodes:
        age = "-" if n.heartbeat_age_s is None else f"{n.heartbeat_age_s:.2f}"
        table.add_row(n.name, "yes" if n.alive else "no", n.state or "-",
                      str(n.pid) if n.pid else "-", age)
    Console(highlight=False).print(table)
    return 0
