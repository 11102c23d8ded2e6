"""Signed bus payloads: who sent a message, proven with the cell's secret (HMAC-SHA256).

A signed payload is the message's encoding followed by a trailer::

    body | signer (u8 length + UTF-8) | role (u8) | session (8 bytes) | counter (u64)
         | t (f64, sender's time.time()) | mac (32 bytes) | trailer length (u16) | MAGIC

``mac = HMAC-SHA256(secret, key expression | 0 | body | trailer fields)``: binding the key
expression means a signed command to one node cannot be replayed to another. Replay of the
same payload is refused by the receiver: its time must be within ``WINDOW_S`` of the
receiver's clock and its (session, counter) not seen before (a sliding window per sending
session). Roles: ``node`` (a process of the launched cell) and ``operator`` (the CLI, the
console): any holder of the secret can claim either, so the roles express what a sender is
for; the secret is what keeps everyone else out.
"""

from __future__ import annotations

import hashlib
import hmac
import itertools
import os
import struct
import threading
import time
from dataclasses import dataclass
from enum import StrEnum

MAGIC = b"\xa7MSG"
_FIXED = struct.Struct("<B8sQd")  # role, session, counter, t
_TAIL = struct.Struct("<H4s")  # trailer length, magic
MAC_BYTES = 32
WINDOW_S = 10.0  # s a signed payload stays acceptable (clock skew + bus delay)
REPLAY_WINDOW = 4096  # counters of one session remembered out of order


class Role(StrEnum):
    """What a signer is for."""

    NODE = "node"
    OPERATOR = "operator"


_ROLES = tuple(Role)


@dataclass(frozen=True)
class Signer:
    """A proven sender: its bus name, role and session (random per bus session, so a
    restarted process is a new session)."""

    name: str
    role: Role
    session: bytes = b""


@dataclass(frozen=True)
class Opened:
    """A received payload: the message bytes, the signer (None if not proven) and why not."""

    body: bytes
    signer: Signer | None
    why: str = ""


class Signing:
    """Signs the payloads one bus session sends, as ``name`` in ``role``."""

    def __init__(self, secret: bytes, name: str, role: Role) -> None:
        self._secret = secret
        self.name = name
        self.role = role
        self._session = os.urandom(8)
        self._counter = itertools.count(1)

    def sign(self, key_expr: str, body: bytes, role: Role | None = None) -> bytes:
        """``body`` with a trailer proving it was sent on ``key_expr`` by this session."""
        name = self.name.encode()
        fields = (bytes([len(name)]) + name
                  + _FIXED.pack(_ROLES.index(role or self.role), self._session,
                                next(self._counter), time.time()))
        mac = hmac.new(self._secret, key_expr.encode() + b"\0" + body + fields,
                       hashlib.sha256).digest()
        trailer = fields + mac
        return body + trailer + _TAIL.pack(len(trailer), MAGIC)


def split(payload: bytes) -> tuple[bytes, bytes]:
    """(body, trailer) of a payload; the trailer is b"" when there is none."""
    if len(payload) >= _TAIL.size and payload[-4:] == MAGIC:
        n, _ = _TAIL.unpack_from(payload, len(payload) - _TAIL.size)
        end = len(payload) - _TAIL.size
        if _FIXED.size + MAC_BYTES + 1 <= n <= end:
            return payload[: end - n], payload[end - n : end]
    return payload, b""


class Verifier:
    """Checks signed payloads against the cell's secret and refuses replays.

    One verifier per subscription or queryable: each remembers the counters it has seen.
    """

    def __init__(self, secret: bytes | None) -> None:
        self._secret = secret
        self._seen: dict[bytes, tuple[int, set[int]]] = {}
        self._lock = threading.Lock()

    def open(self, key_expr: str, payload: bytes) -> Opened:
        """The body of ``payload`` and its proven signer, or why it is not proven."""
        body, trailer = split(payload)
        if not trailer:
            return Opened(body, None, "unsigned")
        if self._secret is None:
            return Opened(body, None, "this process holds no cell secret")
        n = trailer[0]
        if len(trailer) != 1 + n + _FIXED.size + MAC_BYTES:
            return Opened(body, None, "malformed signature")
        fields, mac = trailer[:-MAC_BYTES], trailer[-MAC_BYTES:]
        want = hmac.new(self._secret, key_expr.encode() + b"\0" + body + fields,
                        hashlib.sha256).digest()
        if not hmac.compare_digest(mac, want):
            return Opened(body, None, "bad signature (not signed with this cell's secret)")
        try:
            name = fields[1 : 1 + n].decode()
        except UnicodeDecodeError:
            return Opened(body, None, "malformed signature")
        role_i, session, counter, t = _FIXED.unpack_from(fields, 1 + n)
        if role_i >= len(_ROLES):
            return Opened(body, None, "malformed signature")
        if abs(time.time() - t) > WINDOW_S:
            return Opened(body, None, f"stale signature ({time.time() - t:+.1f} s old)")
        if not self._fresh(session, counter):
            return Opened(body, None, "replayed message")
        return Opened(body, Signer(name, _ROLES[role_i], session))

    def _fresh(self, session: bytes, counter: int) -> bool:
        """Whether ``counter`` of ``session`` is new (within the sliding window)."""
        with self._lock:
            top, seen = self._seen.get(session, (0, set()))
            if counter <= top - REPLAY_WINDOW or counter in seen:
                return False
            seen.add(counter)
            if counter > top:
                top = counter
                if len(seen) > 2 * REPLAY_WINDOW:
                    seen = {c for c in seen if c > top - REPLAY_WINDOW}
            self._seen[session] = (top, seen)
            if len(self._seen) > 1024:  # sessions long gone: keep the newest
                for old in list(self._seen)[: len(self._seen) - 1024]:
                    del self._seen[old]
            return True
