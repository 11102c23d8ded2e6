"""One zenoh session per process, with typed publish/subscribe, commands and presence.

Peer mode on loopback by default with multicast scouting off: every endpoint is explicit
(``listen``/``connect``), so the same processes run across hosts by pointing ``connect`` at a
zenoh router or at another host's peer. Peers that connect to one common endpoint find each
other through gossip and form a mesh, so messages between two nodes take one hop.

Every payload a session sends is signed with the cell's secret (``signing``, ``secret``), and
what it receives is checked: a subscription takes only messages proven to come from the node
whose key they are on, a command server passes the proven sender to its ``authorize`` check,
a request takes only a reply signed by the node asked, and presence needs the node's signed
heartbeats as well as its liveliness token (``presence``). Anything refused is dropped, counted
in ``refused`` and logged (at most once per key and reason every 10 s).
"""

from __future__ import annotations

import json
import logging
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

from core.errors import InputError
from mesp_cell.bus.codec import CodecError, decode, encode
from mesp_cell.bus.keys import check_part, key, liveliness_key, parse_key
from mesp_cell.bus.secret import cell_secret
from mesp_cell.bus.signing import Role, Signer, Signing, Verifier, split
from mesp_cell.bus.tls import apply_tls, tls_folder
from mesp_cell.heap import TRIM_AFTER_S, give_back
from mesp_cell.messages import Command, Reply

T = TypeVar("T")
log = logging.getLogger("mesp.bus")

#: ``subscribe(sender=ANYONE)``: accept unsigned messages too.
ANYONE = "*"
#: Shared keys whose messages anyone may send: an e-stop is obeyed whoever sends it (stopping
#: is always safe; refusing a stop because of its sender never is).
OPEN_NODES = frozenset({"estop"})
#: Periodic topics: a message dropped under congestion is superseded by the next one.
LOSSY_TOPICS = frozenset({"state", "heartbeat", "progress"})
#: ``Bus(secret=AUTO)``: the cell's secret from ``$MESP_HOME`` (made at first start).
AUTO = b"auto"
#: Decides a command: '' to accept, else the one-line reason it is refused.
Authorize = Callable[[Command, "Signer | None"], str]


@dataclass(frozen=True)
class BusConfig:
    """Where a process joins the bus.

    Attributes:
        cell: cell name, the second part of every key.
        listen: zenoh endpoints this process listens on (``tcp/127.0.0.1:0`` = any free port).
        connect: endpoints it connects to (the launcher's hub, or a router).
        mode: zenoh mode, "peer" or "client".
        multicast: multicast scouting (off by default: endpoints are explicit).
        tls_dir: folder of the cell's TLS certificates and access control (``bus.tls``; ""
            = ``$MESP_BUS_TLS`` if set, else plain TCP on loopback).
    """

    cell: str = "sim"
    listen: tuple[str, ...] = ("tcp/127.0.0.1:0",)
    connect: tuple[str, ...] = ()
    mode: str = "peer"
    multicast: bool = False
    tls_dir: str = ""

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
             "mode": self.mode, "multicast": self.multicast, "tls_dir": self.tls_dir}
        )

    @staticmethod
    def from_json(text: str) -> BusConfig:
        """Inverse of ``to_json``."""
        data = json.loads(text)
        return BusConfig(
            cell=data["cell"], listen=tuple(data["listen"]), connect=tuple(data["connect"]),
            mode=data.get("mode", "peer"), multicast=bool(data.get("multicast", False)),
            tls_dir=str(data.get("tls_dir", "")),
        )


def _matching(entity: Any) -> bool:
    """Whether a zenoh publisher or querier has a matching peer (its stub says a bool; it is a
    ``MatchingStatus``)."""
    status: Any = entity.matching_status
    return bool(status.matching)


def _zenoh_config(cfg: BusConfig) -> Any:
    import zenoh

    zc = zenoh.Config()
    zc.insert_json5("mode", json.dumps(cfg.mode))
    zc.insert_json5("scouting/multicast/enabled", "true" if cfg.multicast else "false")
    zc.insert_json5("listen/endpoints", json.dumps(list(cfg.listen) if cfg.mode == "peer" else []))
    zc.insert_json5("connect/endpoints", json.dumps(list(cfg.connect)))
    folder = tls_folder(cfg.tls_dir)
    if folder is not None:
        apply_tls(zc, folder)
    return zc


class Bus:
    """A process's handle on the cell bus, as node ``node`` of cell ``config.cell``.

    ``role``: what this session signs as (a launched node, or the operator's CLI/console).
    ``secret``: the cell's key (``AUTO``: read or made in ``$MESP_HOME``; None: unsigned, a
    session that nothing on a secured cell obeys).
    """

    def __init__(self, config: BusConfig, node: str, role: Role = Role.OPERATOR,
                 secret: bytes | None = AUTO) -> None:
        import zenoh

        self.config = config
        self.node = check_part(node, "node name")
        key_bytes = cell_secret(config.cell) if secret is AUTO else secret
        self.secret = key_bytes
        self.signing = Signing(key_bytes, self.node, role) if key_bytes else None
        self.refused = 0  # messages and commands refused (unsigned, forged, replayed, denied)
        self.default_authorize: Authorize | None = None  # ``serve``'s check unless given one
        self._refusal_logged: dict[tuple[str, str], float] = {}
        self._zenoh = zenoh
        self._session = zenoh.open(_zenoh_config(config))
        self._publishers: dict[str, Any] = {}
        self._keep: list[Any] = []  # declared entities live as long as the bus
        self._lock = threading.Lock()
        self._closed = False
        self.dropped = 0  # payloads of the wrong type or corrupt, dropped by subscribers
        self._workers: list[queue.Queue[Any]] = []
        self._watches: list[Any] = []  # presence.PresenceWatch of ``watch_presence``

    # -- keys ------------------------------------------------------------------------------
    def key(self, topic: str, node: str | None = None) -> str:
        """``mesp/<cell>/<node>/<topic>``; ``node`` defaults to this process."""
        return key(self.config.cell, node or self.node, topic)

    # -- publish/subscribe -----------------------------------------------------------------
    def publish(self, topic: str, message: Any, express: bool = True) -> None:
        """Publish a message on this node's ``topic`` (a declared publisher is reused).

        A periodic topic (``LOSSY_TOPICS``) may drop a message when the link is congested (the
        next one supersedes it); any other (stream events, waypoints) waits for room instead:
        a dropped end-of-stream event left a supervisor waiting for it for good.
        """
        k = self.key(topic)
        self._publisher(topic, express).put(self._sign(k, encode(message)))

    def _publisher(self, topic: str, express: bool = True) -> Any:
        """The declared zenoh publisher of this node's ``topic`` (declared on first use)."""
        k = self.key(topic)
        with self._lock:
            pub = self._publishers.get(k)
            if pub is None:
                z = self._zenoh
                lossy = topic.split("/")[-1] in LOSSY_TOPICS
                congestion = z.CongestionControl.DROP if lossy else z.CongestionControl.BLOCK
                pub = self._session.declare_publisher(
                    k, congestion_control=congestion, express=express,
                    priority=z.Priority.REAL_TIME,
                )
                self._publishers[k] = pub
        return pub

    def wait_subscribed(self, topic: str, timeout: float = 5.0) -> bool:
        """Wait until some session subscribes to this node's ``topic``; whether one did.

        A subscription takes a moment to reach the publisher's router; what is published before
        that is lost, so a publisher whose first message matters waits here first.
        """
        pub = self._publisher(topic)
        end = time.monotonic() + timeout
        while not _matching(pub):
            if time.monotonic() >= end:
                return False
            time.sleep(0.01)
        return True

    def publish_to(self, node: str, topic: str, message: Any) -> None:
        """Publish on another node's key (used for the shared ``estop`` topic)."""
        z = self._zenoh
        k = key(self.config.cell, node, topic)
        self._session.put(
            k, self._sign(k, encode(message)),
            congestion_control=z.CongestionControl.BLOCK, priority=z.Priority.REAL_TIME,
            express=True,
        )

    # -- signing -----------------------------------------------------------------------------
    def _sign(self, key_expr: str, body: bytes, role: Role | None = None) -> bytes:
        return self.signing.sign(key_expr, body, role) if self.signing else body

    def refuse(self, key_expr: str, why: str) -> None:
        """Count and log a refused message or command (rate-limited per key and reason)."""
        self.refused += 1
        now = time.monotonic()
        k = (key_expr, why.split(" (")[0])
        if now - self._refusal_logged.get(k, -1e9) >= 10.0:
            self._refusal_logged[k] = now
            log.warning("%s refused a message on %s: %s", self.node, key_expr, why)

    def sender_ok(self, key_expr: str, signer: Signer | None, why: str, sender: str | None) -> bool:
        """Whether a message on ``key_expr`` comes from whom it must (``subscribe``)."""
        if sender == ANYONE:
            return True
        if sender is None:
            try:
                if parse_key(key_expr).node in OPEN_NODES:
                    return True
            except ValueError:
                pass
        if signer is None:
            self.refuse(key_expr, why)
            return False
        want = sender
        if want is None:
            try:
                want = parse_key(key_expr).node
            except ValueError:
                want = ""
        if signer.name != want:
            self.refuse(key_expr, f"signed by {signer.name}, not {want}")
            return False
        return True

    def subscribe(
        self, node: str, topic: str, kind: type[T], callback: Callable[[T], None],
        sender: str | None = None,
    ) -> None:
        """Call ``callback(message)`` for every ``kind`` message on ``<node>/<topic>``.

        ``node`` may be ``*``. Only messages signed with the cell's secret by ``sender``
        (default: the node whose key it is; anyone on the shared ``OPEN_NODES`` keys) are
        passed on; ``sender=ANYONE`` takes unsigned ones too. Payloads of another type or
        corrupt ones are dropped (counted in ``dropped``) rather than crashing the zenoh
        callback thread; unproven ones are refused (``refuse``).
        """
        verifier = Verifier(self.secret)

        def on_sample(sample: Any) -> None:
            k = str(sample.key_expr)
            opened = verifier.open(k, sample.payload.to_bytes())
            if not self.sender_ok(k, opened.signer, opened.why, sender):
                return
            try:
                msg = decode(opened.body, kind)
            except CodecError:
                self.dropped += 1
                return
            callback(msg)

        sub = self._session.declare_subscriber(key(self.config.cell, node, topic), on_sample)
        self._keep.append(sub)

    def subscribe_raw(self, key_expr: str, callback: Callable[[str, bytes], None]) -> None:
        """Call ``callback(key, payload)`` for every sample on ``key_expr`` (wildcards allowed),
        undecoded and unchecked (the signature removed): for tools that look at every topic
        whatever its type (``mesp topic``), never for acting on."""
        sub = self._session.declare_subscriber(
            key_expr,
            lambda sample: callback(str(sample.key_expr), split(sample.payload.to_bytes())[0]))
        self._keep.append(sub)

    # -- commands (request/reply) ----------------------------------------------------------
    def serve(self, handler: Callable[[Command], Reply], topic: str = "cmd",
              authorize: Authorize | None = None) -> None:
        """Answer ``Command`` queries on this node's ``topic`` with ``handler``.

        ``authorize(command, signer)`` decides first (default: any sender proven to hold the
        cell's secret); a refusal is the reply, counted and logged.

        The handler runs on a worker thread of its own, one command at a time, and the reply
        is sent from there: zenoh's callback threads only queue the query, so a long command
        (slicing for minutes, a process pool, a nested request) never blocks the session. A
        handler exception becomes a refusal naming it, so a caller always gets one line.
        After a command that took ``heap.TRIM_AFTER_S`` or more, the freed heap goes back to
        the OS (``heap.give_back``).
        """
        pending: queue.Queue[Any] = queue.Queue()
        verifier = Verifier(self.secret)
        k = self.key(topic)

        def member(cmd: Command, signer: Signer | None) -> str:
            return "" if signer is not None else "the sender does not hold the cell's secret"

        check = authorize or self.default_authorize or member

        def answer(query: Any) -> None:
            cmd: Command | None = None
            started = time.monotonic()
            try:
                payload = query.payload
                opened = verifier.open(k, payload.to_bytes() if payload is not None else b"")
                cmd = decode(opened.body, Command)
                denied = check(cmd, opened.signer)
                if denied:
                    self.refuse(k, f"{cmd.verb}: {denied}"
                                   + (f" ({opened.why})" if opened.signer is None else ""))
                    reply = Reply.refuse(f"{self.node} refused {cmd.verb}: {denied}")
                else:
                    reply = handler(cmd)
            except InputError as exc:
                reply = Reply.refuse(exc.one_line())
            except CodecError as exc:
                reply = Reply.refuse(f"malformed command ({exc})")
            except Exception as exc:  # a reply must always go out; the traceback goes to the log
                log.exception("command %s on %s failed", getattr(cmd, "verb", "?"), self.node)
                reply = Reply.refuse(f"{type(exc).__name__}: {exc}")
            try:
                query.reply(query.key_expr, self._sign(str(query.key_expr), encode(reply)))
            finally:
                query.drop()  # completes the query for the caller
            if time.monotonic() - started >= TRIM_AFTER_S:
                give_back()  # the heap a long command grew, back to the OS (``heap``)

        def worker() -> None:
            while True:
                query = pending.get()
                if query is None:
                    return
                answer(query)

        thread = threading.Thread(target=worker, name=f"{self.node}-{topic}", daemon=True)
        thread.start()
        self._workers.append(pending)
        q = self._session.declare_queryable(k, pending.put)
        self._keep.append(q)

    def request(
        self, node: str, command: Command, timeout: float = 5.0, topic: str = "cmd"
    ) -> Reply:
        """Send ``command`` to ``<node>/<topic>`` (signed) and wait for the reply.

        Only a reply signed by ``node`` counts (another session answering in its place is
        refused). Never raises for a missing node: the reply is a refusal saying nobody
        answered.
        """
        k = key(self.config.cell, node, topic)
        replies = self._session.get(k, payload=self._sign(k, encode(command)), timeout=timeout)
        verifier = Verifier(self.secret)
        for r in replies:
            if r.ok is not None:
                opened = verifier.open(str(r.ok.key_expr), r.ok.payload.to_bytes())
                if self.secret is not None and not self.sender_ok(
                        str(r.ok.key_expr), opened.signer, opened.why, node):
                    continue
                try:
                    return decode(opened.body, Reply)
                except CodecError as exc:
                    return Reply.refuse(f"{node} sent a malformed reply ({exc})")
        return Reply.refuse(
            f"no reply from node '{node}' of cell '{self.config.cell}' within {timeout:g} s"
        )

    def wait_served(self, node: str, topic: str = "cmd", timeout: float = 5.0) -> bool:
        """Wait until ``<node>/<topic>`` has a server this session can reach; whether it has."""
        querier = self._session.declare_querier(key(self.config.cell, node, topic))
        try:
            end = time.monotonic() + timeout
            while not _matching(querier):
                if time.monotonic() >= end:
                    return False
                time.sleep(0.01)
            return True
        finally:
            querier.undeclare()

    # -- presence --------------------------------------------------------------------------
    def announce(self) -> None:
        """Declare this process's liveliness token (removed by zenoh when the process dies)."""
        tok = self._session.liveliness().declare_token(liveliness_key(self.config.cell, self.node))
        self._keep.append(tok)

    def watch_presence(self, callback: Callable[[str, bool], None]) -> None:
        """Call ``callback(node, alive)`` when a node appears or disappears.

        With the cell's secret a node is present while it holds its liveliness token and its
        signed heartbeats keep coming (``presence.PresenceWatch``: a token alone can be
        forged); without, its token alone counts. Nodes present when the watch starts are
        reported as appearing.
        """
        if self.secret is not None:
            from mesp_cell.bus.presence import PresenceWatch

            self._watches.append(PresenceWatch(self, callback))
            return
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

    def presence_warm(self, timeout: float = 1.5) -> None:
        """Wait until this session's presence watches have seen every node's heartbeat (a node
        calls it before it announces itself, so when it counts as up, so does its view)."""
        for watch in self._watches:
            watch.warm(timeout)

    def keep(self, entity: Any) -> None:
        """Keep a declared zenoh entity until the bus closes."""
        self._keep.append(entity)

    @property
    def closed(self) -> bool:
        """The session is closed."""
        return self._closed

    def alive_nodes(self, timeout: float = 1.0) -> set[str]:
        """Names of the nodes whose liveliness token is present now (tokens only: for
        display and tests; what acts on presence uses ``watch_presence``)."""
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
