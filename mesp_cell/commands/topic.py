"""`mesp topic list|echo|hz`: what a running cell publishes, like ``ros2 topic``."""

from __future__ import annotations

import argparse
import threading
import time
from typing import Any

import numpy as np

KEY_HELP = "NODE/TOPIC (e.g. robot/state, extruder/state, */heartbeat) or a full mesp/... key"


def register(sub: Any) -> None:
    """Add the `topic` sub-command."""
    p = sub.add_parser("topic", help="topics of a running cell: list, echo, hz",
                       description="Look at the messages on a running cell's bus, decoded with "
                       "the cell's codec (mesp_cell/messages.py lists the topics).")
    p.add_argument("--on", metavar="CELL", default=None,
                   help="name of the running cell (default: the only one running, else 'sim')")
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    actions.required = True
    ls = actions.add_parser("list", help="keys published on, with type, count and rate")
    ls.add_argument("--listen", type=float, default=2.0, metavar="S",
                    help="how long to listen (default 2 s)")
    ls.set_defaults(func=list_topics)
    ec = actions.add_parser("echo", help="print each message as one JSON line")
    ec.add_argument("key", metavar="KEY", help=KEY_HELP)
    ec.add_argument("--count", "-n", type=int, default=0, metavar="N",
                    help="stop after N messages (default: until Ctrl-C)")
    ec.add_argument("--timeout", type=float, default=5.0, metavar="S",
                    help="fail if no message arrives within S s (default 5)")
    ec.set_defaults(func=echo_topic)
    hz = actions.add_parser("hz", help="message rate of a key, printed every second")
    hz.add_argument("key", metavar="KEY", help=KEY_HELP)
    hz.add_argument("--duration", type=float, default=0.0, metavar="S",
                    help="stop after S s (default: until Ctrl-C)")
    hz.add_argument("--window", type=int, default=1000, metavar="N",
                    help="rate over the last N messages (default 1000)")
    hz.set_defaults(func=hz_topic)


def list_topics(args: argparse.Namespace) -> int:
    """Print one table row per key heard."""
    from rich.console import Console
    from rich.table import Table

    from mesp_cell.cell_client import CellClient
    from mesp_cell.introspect import topic_list

    client = CellClient.for_cell(args.on)
    try:
        topics = topic_list(client.bus(), args.listen)
    finally:
        client.close()
    table = Table(title=f"topics of cell '{client.cell}' heard in {args.listen:g} s",
                  title_justify="left")
    for col in ("key", "type", "messages", "rate (Hz)"):
        table.add_column(col, justify="right" if col in ("messages", "rate (Hz)") else "left")
    for t in topics:
        table.add_row(t.key, t.type, str(t.count), f"{t.hz:.1f}")
    Console(highlight=False, width=200).print(table)
    return 0


def echo_topic(args: argparse.Namespace) -> int:
    """Print messages until ``--count`` or Ctrl-C."""
    from mesp_cell.cell_client import CellClient
    from mesp_cell.introspect import echo, resolve_key

    client = CellClient.for_cell(args.on)
    try:
        key = resolve_key(client.cell, args.key)
        echo(client.bus(), key, lambda text: print(text, flush=True), args.count, args.timeout)
    finally:
        client.close()
    return 0


def hz_topic(args: argparse.Namespace) -> int:
    """Print the rate of a key once a second."""
    from mesp_cell.cell_client import CellClient
    from mesp_cell.introspect import rate_stats, resolve_key

    client = CellClient.for_cell(args.on)
    arrivals: list[float] = []
    lock = threading.Lock()

    def on(_key: str, _payload: bytes) -> None:
        with lock:
            arrivals.append(time.monotonic())

    try:
        key = resolve_key(client.cell, args.key)
        client.bus().subscribe_raw(key, on)
        start = time.monotonic()
        while not args.duration or time.monotonic() - start < args.duration:
            time.sleep(1.0)
            with lock:
                recent = np.array(arrivals[-args.window:])
            stats = rate_stats(recent)
            if stats is None:
                print(f"{key}: no messages yet", flush=True)
                continue
            print(f"{key}: average rate {stats.hz:.2f} Hz  min {stats.min_s:.4f} s  "
                  f"max {stats.max_s:.4f} s  std dev {stats.std_s:.5f} s  window {stats.n}",
                  flush=True)
    finally:
        client.close()
    return 0
