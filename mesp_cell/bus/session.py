"""One zenoh session per process, with typed publish/subscribe, commands and presence.

Peer mode on loopback by default with multicast scouting off: every endpoint is explicit
(``listen``/``connect``), so the same processes run across hosts by pointing ``connect`` at a
zenoh router or at another host's peer. Peers that connect to one common endpoint find each
other through gossip and form a mesh, so messages between two nodes take one hop.
"""

from __future__ import annotations

import json
import logging
import queue
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

from core.errors import InputError
from mesp_cell.bus.codec import CodecError, decode, encode
from mesp_cell.bus.keys import check_part, key, liveliness_key, parse_key
from mesp_cell.messages import Command, Reply

T = TypeVar("T")
log = logging.getLogger("mesp.bus")


@dataclass(frozen=True)
class BusConfig:
    """Where a process joins the bus.

    Attributes:
        cell: cell name, the second part of every key.
        listen: zenoh endpoints this process listens on (``tcp/127.0.0.1:0`` = any free port).
        connect: endpoints it connects to (the launcher's hub, or a router).
        mode: zenoh mode, "peer" or "client".
        multicast: multicast scouting (off by default: endpoints are explicit).
    """

    cell: str = "sim"
    listen: tuple[str, ...] = ("tcp/127.0.0.1:0",)
    connect: tuple[str, ...] = ()
    mode: str = "peer"
    multicast: bool = False

    def __post_init__(self) -> None:
        check_part(self.cell, "cell name")
        if self.mode not in ("peer", "client"):
            raise InputError(f"bus mode '{self.mode}' is not supported", "use 'peer' or 'client'")
        for ep in (*self.listen, *self.connect):
            if "/" not in ep:
                raise InputError(f"bus endpoint '{ep}' is malformed",
                                 "write e.g. tcp/127.0.0.1:7447")

    def to_json(self) -> str:
        """The config as JSON text (passed to child processes)."""
        return json.dumps(
            {"cell": self.cell, "listen": list(self.listen), "connect": list(self.connect),
             "mode": self.mode, "multicast": self.multicast}
        )

    @staticmethod
    def from_json(text: str) -> BusConfig:
        """Inverse of ``to_json``."""
        data = json.loads(text)
        return BusConfig(
            cell=data["cell"], listen=tuple(data["listen"]), connect=tuple(data["connect"]),
            mode=data.get("mode", "peer"), multicast=bool(data.get("multicast", False)),
        )


def _zenoh_config(cfg: BusConfig) -> Any:
    import zenoh

    zc = zenoh.Config()
    zc.insert_json5("mode", json.dumps(cfg.mode))
    zc.insert_json5("scouting/multicast/enabled", "true" if cfg.multicast else "false")
    zc.insert_json5("listen/endpoints", json.dumps(list(cfg.listen) if cfg.mode == "peer" else []))
    zc.insert_json5("connect/endpoints", json.dumps(list(cfg.connect)))
    return zc


class Bus:
    """A process's handle on the cell bus, as node ``node`` of cell ``config.cell``."""

    def __init__(self, config: BusConfig, node: str) -> None:
        import zenoh

        self.config = config
        self.node = check_part(node, "node name")
        self._zenoh = zenoh
        self._session = zenoh.open(_zenoh_config(config))
        self._publishers: dict[str, Any] = {}
        self._keep: list[Any] = []  # declared entities live as long as the bus
        self._lock = threading.Lock()
        self._closed = False
        self.dropped = 0  # payloads of the wrong type or corrupt, dropped by subscribers
        self._workers: list[queue.Queue[Any]] = []

    # -- keys ------------------------------------------------------------------------------
    def key(self, topic: str, node: str | None = None) -> str:
        """``mesp/<cell>/<node>/<topic>``; ``node`` defaults to this process."""
        return key(self.config.cell, node or self.node, topic)

    # -- publish/subscribe -----------------------------------------------------------------
    def publish(self, topic: str, message: Any, express: bool = True) -> None:
        """Publish a message on this node's ``topic`` (a declared publisher is reused)."""
        k = self.key(topic)
        with self._lock:
            pub = self._publishers.get(k)
            if pub is None:
                z = self._zenoh
                pub = self._session.declare_publisher(
                    k, congestion_control=z.CongestionControl.DROP, express=express,
                    priority=z.Priority.REAL_TIME,
                )
                self._publishers[k] = pub
        pub.put(encode(message))

    def publish_to(self, node: str, topic: str, message: Any) -> None:
        """Publish on another node's key (used for the shared ``estop`` topic)."""
        z = self._zenoh
        self._session.put(
            key(self.config.cell, node, topic), encode(message),
            congestion_control=z.CongestionControl.BLOCK, priority=z.Priority.REAL_TIME,
            express=True,
        )

    def subscribe(
        self, node: str, topic: str, kind: type[T], callback: Callable[[T], None]
    ) -> None:
        """Call ``callback(message)`` for every ``kind`` message on ``<node>/<topic>``.

        ``node`` may be ``*``. Payloads of another type or corrupt ones are dropped (counted
        in ``dropped``) rather than crashing the zenoh callback thread.
        """

        def on_sample(sample: Any) -> None:
            try:
                msg = decode(sample.payload.to_bytes(), kind)
            except CodecError:
                self.dropped += 1
                return
            callback(msg)

        sub = self._session.declare_subscriber(key(self.config.cell, node, topic), on_sample)
        self._keep.append(sub)

    def subscribe_raw(self, key_expr: str, callback: Callable[[str, bytes], None]) -> None:
        """Call ``callback(key, payload)`` for every sample on ``key_expr`` (wildcards allowed),
        undecoded: for tools that look at every topic whatever its type (``mesp topic``)."""
        sub = self._session.declare_subscriber(
            key_expr, lambda sample: callback(str(sample.key_expr), sample.payload.to_bytes()))
        self._keep.append(sub)

    # -- commands (request/reply) ----------------------------------------------------------
    def serve(self, handler: Callable[[Command], Reply], topic: str = "cmd") -> None:
        """Answer ``Command`` queries on this node's ``topic`` with ``handler``.

        The handler runs on a worker thread of its own, one command at a time, and the reply
        is sent from there: zenoh's callback threads only queue the query, so a long command
        (slicing for minutes, a process pool, a nested request) never blocks the session. A
        handler exception becomes a refusal naming it, so a caller always gets one line.
        """
        pending: queue.Queue[Any] = queue.Queue()

        def answer(query: Any) -> None:
            cmd: Command | None = None
            try:
                payload = query.payload
                cmd = decode(payload.to_bytes() if payload is not None else b"", Command)
                reply = handler(cmd)
            except InputError as exc:
                reply = Reply.refuse(exc.one_line())
            except CodecError as exc:
                reply = Reply.refuse(f"malformed command ({exc})")
            except Exception as exc:  # a reply must always go out; the traceback goes to the log
                log.exception("command %s on %s failed", getattr(cmd, "verb", "?"), self.node)
                reply = Reply.refuse(f"{type(exc).__name__}: {exc}")
            try:
                query.reply(query.key_expr, encode(reply))
            finally:
                query.drop()  # completes the query for the caller

        def worker() -> None:
            while True:
                query = pending.get()
                if query is None:
                    return
                answer(query)

        thread = threading.Thread(target=worker, name=f"{self.node}-{topic}", daemon=True)
        thread.start()
        self._workers.append(pending)
        q = self._session.declare_queryable(self.key(topic), pending.put)
        self._keep.append(q)

    def request(
        self, node: str, command: Command, timeout: float = 5.0, topic: str = "cmd"
    ) -> Reply:
        """Send ``command`` to ``<node>/<topic>`` and wait for the reply.

        Never raises for a missing node: the reply is a refusal saying nobody answered.
        """
        k = key(self.config.cell, node, topic)
        replies = self._session.get(k, payload=encode(command), timeout=timeout)
        for r in replies:
            if r.ok is not None:
                try:
                    return decode(r.ok.payload.to_bytes(), Reply)
                except CodecError as exc:
                    return Reply.refuse(f"{node} sent a malformed reply ({exc})")
        return Reply.refuse(
            f"no reply from node '{node}' of cell '{self.config.cell}' within {timeout:g} s"
        )

    # -- presence --------------------------------------------------------------------------
    def announce(self) -> None:
        """Declare this process's liveliness token (removed by zenoh when the process dies)."""
        tok = self._session.liveliness().declare_token(liveliness_key(self.config.cell, self.node))
        self._keep.append(tok)

    def watch_presence(self, callback: Callable[[str, bool], None]) -> None:
        """Call ``callback(node, alive)`` when a node's token appears or disappears.

        Tokens present when the watch starts are reported as appearing.
        """
        z = self._zenoh

        def on_sample(sample: Any) -> None:
            try:
                parts = parse_key(str(sample.key_expr))
            except ValueError:
                return
            callback(parts.node, sample.kind == z.SampleKind.PUT)

        sub = self._session.liveliness().declare_subscriber(
            key(self.config.cell, "*", "alive"), on_sample, history=True
        )
        self._keep.append(sub)

    def alive_nodes(self, timeout: float = 1.0) -> set[str]:
        """Names of the nodes whose liveliness token is present now."""
        out: set[str] = set()
        for r in self._session.liveliness().get(key(self.config.cell, "*", "alive"),
                                                timeout=timeout):
            if r.ok is not None:
                try:
                    out.add(parse_key(str(r.ok.key_expr)).node)
                except ValueError:
                    continue
        return out

    def close(self) -> None:
        """Undeclare everything and close the session (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for pending in self._workers:
            pending.put(None)
        for pub in self._publishers.values():
            pub.undeclare()
        for item in reversed(self._keep):
            try:
                item.undeclare()
            except Exception:  # already gone with the session; nothing to release
                pass
        self._session.close()

    def __enter__(self) -> Bus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
