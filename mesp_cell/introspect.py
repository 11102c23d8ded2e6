"""What is on a running cell's bus: nodes, topics, messages and their rates.

The counterpart of ``ros2 node list`` / ``ros2 topic list|echo|hz``: a bus session listens
for a while and decodes every payload with the project's codec (``mesp_cell.bus.codec``).
Keys are given as ``<node>/<topic>`` (``robot/state``; ``*`` allowed) or in full
(``mesp/<cell>/<node>/<topic>``).
"""

from __future__ import annotations

import dataclasses
import json
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from core.errors import InputError
from mesp_cell.bus.codec import CodecError, decode
from mesp_cell.bus.keys import PREFIX, check_part, key, parse_key
from mesp_cell.bus.session import Bus
from mesp_cell.messages import Heartbeat


@dataclass(frozen=True)
class NodeInfo:
    """One node as the bus shows it.

    Attributes:
        name: node name. alive: its liveliness token is present.
        state: lifecycle state from its last heartbeat ("" if none was heard).
        pid: OS process id from the heartbeat (0 if none). heartbeat_age_s: s since the last
        heartbeat was sent (None if none was heard while listening).
    """

    name: str
    alive: bool
    state: str
    pid: int
    heartbeat_age_s: float | None


@dataclass(frozen=True)
class TopicInfo:
    """One key heard while listening: its message type, count and mean rate (Hz)."""

    key: str
    type: str
    count: int
    hz: float


def resolve_key(cell: str, text: str) -> str:
    """The full key expression of ``text`` (``node/topic`` or ``mesp/<cell>/...``)."""
    parts = text.strip("/").split("/")
    if parts[0] == PREFIX:
        parsed = parse_key(text.strip("/"))
        return key(parsed.cell, parsed.node, parsed.topic)
    if len(parts) < 2:
        raise InputError(f"'{text}' is not a topic key",
                         "write NODE/TOPIC, e.g. robot/state (see `mesp topic list`)")
    check_part(parts[0], "node name", wildcard=True)
    return key(cell, parts[0], "/".join(parts[1:]))


def message_text(payload: bytes) -> tuple[str, dict[str, Any] | str]:
    """(type name, fields) of a payload; ("?", reason) if the codec cannot read it."""
    try:
        msg: Any = decode(payload)
    except CodecError as exc:
        return "?", f"undecodable ({exc}; {len(payload)} bytes)"
    return type(msg).__name__, dataclasses.asdict(msg)


def listen(bus: Bus, key_expr: str, seconds: float) -> list[tuple[float, str, bytes]]:
    """Every (arrival time s, key, payload) on ``key_expr`` during ``seconds``."""
    got: list[tuple[float, str, bytes]] = []
    lock = threading.Lock()

    def on(k: str, payload: bytes) -> None:
        with lock:
            got.append((time.monotonic(), k, payload))

    bus.subscribe_raw(key_expr, on)
    time.sleep(seconds)
    with lock:
        return list(got)


def node_list(bus: Bus, seconds: float = 1.5) -> list[NodeInfo]:
    """The nodes of the cell: liveliness tokens plus the heartbeats heard in ``seconds``."""
    heard = listen(bus, key(bus.config.cell, "*", "heartbeat"), seconds)
    now = time.time()
    beats: dict[str, Heartbeat] = {}
    for _, _, payload in heard:
        try:
            hb = decode(payload, Heartbeat)
        except CodecError:
            continue
        if hb.node not in beats or hb.seq > beats[hb.node].seq:
            beats[hb.node] = hb
    alive = bus.alive_nodes(0.5) - {bus.node}
    names = sorted(alive | set(beats))
    return [NodeInfo(n, n in alive, beats[n].state if n in beats else "",
                     beats[n].pid if n in beats else 0,
                     max(0.0, now - beats[n].t) if n in beats else None) for n in names]


def topic_list(bus: Bus, seconds: float = 2.0) -> list[TopicInfo]:
    """The keys published on while listening ``seconds``, with type, count and rate."""
    heard = listen(bus, f"{PREFIX}/{bus.config.cell}/**", seconds)
    by_key: dict[str, list[tuple[float, bytes]]] = {}
    for t, k, payload in heard:
        by_key.setdefault(k, []).append((t, payload))
    out = []
    for k in sorted(by_key):
        items = by_key[k]
        out.append(TopicInfo(k, message_text(items[-1][1])[0], len(items), len(items) / seconds))
    return out


def echo(bus: Bus, key_expr: str, emit: Callable[[str], None], count: int = 0,
         timeout_s: float = 5.0) -> int:
    """Emit each message on ``key_expr`` as one JSON line until ``count`` (0 = no limit).

    Returns the number emitted. Raises ``InputError`` if nothing arrives within ``timeout_s``.
    """
    lines: list[str] = []
    arrived = threading.Condition()

    def on(k: str, payload: bytes) -> None:
        name, fields = message_text(payload)
        text = json.dumps({"key": k, "type": name, "msg": fields})
        with arrived:
            lines.append(text)
            arrived.notify()

    bus.subscribe_raw(key_expr, on)
    shown = 0
    deadline = time.monotonic() + timeout_s
    while count == 0 or shown < count:
        with arrived:
            if shown == len(lines):
                arrived.wait(0.1)
            batch = lines[shown:]
        if not batch:
            if shown == 0 and time.monotonic() > deadline:
                raise InputError(f"no message on {key_expr} within {timeout_s:g} s",
                                 "check the key with `mesp topic list`")
            continue
        for text in batch[: count - shown if count else None]:
            emit(text)
            shown += 1
    return shown


@dataclass(frozen=True)
class RateStats:
    """Message rate over a window: ``hz`` mean rate; periods in s (min, max, std); n messages."""

    hz: float
    min_s: float
    max_s: float
    std_s: float
    n: int


def rate_stats(arrivals: np.ndarray) -> RateStats | None:
    """Rate statistics of arrival times (K,) float64 s; None with fewer than two."""
    if len(arrivals) < 2:
        return None
    periods = np.diff(np.sort(arrivals))
    mean = float(periods.mean())
    return RateStats(1.0 / mean if mean > 0 else float("inf"), float(periods.min()),
                     float(periods.max()), float(periods.std()), len(arrivals))
