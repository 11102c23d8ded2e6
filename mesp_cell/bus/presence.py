"""Which nodes are on the bus, in a way another session cannot forge.

A zenoh liveliness token says a session holds a key, but any session can declare any key, so
a token alone lets a stranger keep a dead supervisor "present". A node counts as present here
only while its token is there AND a heartbeat signed by it (``mesp_cell.bus.signing``, name
bound to the heartbeat's key) arrived within ``timeout_s`` of its own send time. A node whose
process dies is gone the moment its token goes (zenoh removes it); one whose token is held by
someone else is gone once its signed heartbeats stop for ``timeout_s``, or as soon as a
restarted process of that name beats from a new session (it is reported gone, then back): a
motion made for the old process never goes on for the new one.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from mesp_cell.bus.codec import CodecError, decode
from mesp_cell.bus.keys import key, parse_key
from mesp_cell.bus.signing import Verifier
from mesp_cell.messages import Heartbeat

if TYPE_CHECKING:
    from mesp_cell.bus.session import Bus

log = logging.getLogger("mesp.bus")

#: s without a signed heartbeat after which a node with a token counts as gone. Heartbeats come
#: every 0.5 s, but a node deep in a library call (the slicer meshing) can hold them back for
#: several seconds on a loaded host; a process that dies takes its token with it at once, and a
#: restarted one is noticed at its first beat, so this only bounds a forged token.
TIMEOUT_S = 10.0


class PresenceWatch:
    """Calls ``callback(node, alive)`` when a node becomes present or stops being present."""

    def __init__(self, bus: Bus, callback: Callable[[str, bool], None],
                 timeout_s: float = TIMEOUT_S) -> None:
        self.bus = bus
        self.callback = callback
        self.timeout_s = timeout_s
        self.tokens: set[str] = set()
        self.beats: dict[str, float] = {}  # node -> the send time of its last signed beat
        self.sessions: dict[str, bytes] = {}  # node -> the session its beats come from
        self.present: set[str] = set()
        self._lock = threading.Lock()
        z = bus._zenoh

        def on_token(sample: Any) -> None:
            try:
                node = parse_key(str(sample.key_expr)).node
            except ValueError:
                return
            with self._lock:
                (self.tokens.add if sample.kind == z.SampleKind.PUT else self.tokens.discard)(
                    node)
            self._update(node)

        verifier = Verifier(bus.secret)

        def on_beat(sample: Any) -> None:
            k = str(sample.key_expr)
            opened = verifier.open(k, sample.payload.to_bytes())
            if not bus.sender_ok(k, opened.signer, opened.why, None) or opened.signer is None:
                return
            try:
                hb = decode(opened.body, Heartbeat)
            except CodecError:
                return
            self._on_beat(opened.signer.name, opened.signer.session, hb.t)

        bus.keep(bus._session.declare_subscriber(key(bus.config.cell, "*", "heartbeat"),
                                                 on_beat))
        bus.keep(bus._session.liveliness().declare_subscriber(
            key(bus.config.cell, "*", "alive"), on_token, history=True))
        threading.Thread(target=self._tick, name=f"{bus.node}-presence", daemon=True).start()

    def warm(self, timeout: float) -> bool:
        """Wait until every node holding a token has been seen beating (at most ``timeout``
        s; a watch starts knowing tokens but no beats yet). True if it got there."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            with self._lock:
                if self.tokens <= self.present | {self.bus.node}:
                    return True
            time.sleep(0.02)
        return False

    def _on_beat(self, node: str, session: bytes, sent: float) -> None:
        # the beat's own send time: a late or replayed beat cannot extend presence
        t = min(sent, time.time())
        with self._lock:
            restarted = self.sessions.get(node, session) != session
            self.sessions[node] = session
            if restarted:
                self.beats.pop(node, None)
            elif t <= self.beats.get(node, 0.0):
                return
        if restarted:
            self._update(node)  # the old process is gone
        with self._lock:
            self.beats[node] = t
        self._update(node)

    def _update(self, node: str) -> None:
        now = time.time()
        with self._lock:
            alive = node in self.tokens and now - self.beats.get(node, 0.0) <= self.timeout_s
            changed = alive != (node in self.present)
            if changed:
                (self.present.add if alive else self.present.discard)(node)
        if changed:
            if not alive and node in self.tokens:
                log.warning("%s: %s counts as gone: its token is there but %s", self.bus.node,
                            node, f"no signed heartbeat for {now - self.beats[node]:.1f} s"
                            if node in self.beats else "it restarted")
            self.callback(node, alive)

    def _tick(self) -> None:
        while not self.bus.closed:
            time.sleep(0.1)
            with self._lock:
                nodes = set(self.present) | (self.tokens & set(self.beats))
            for node in nodes:
                self._update(node)
