"""Signed payloads: a valid signature opens, anything else (no trailer, another secret, a
changed byte, another key expression, a replay, a stale time) does not."""

from __future__ import annotations

import struct

import pytest

from mesp_cell.bus import signing
from mesp_cell.bus.signing import Role, Signing, Verifier, split

KEY = b"k" * 32
K = "mesp/sim/robot/cmd"


def test_a_signed_payload_opens_once_with_its_signer() -> None:
    s = Signing(KEY, "supervisor", Role.NODE)
    payload = s.sign(K, b"body")
    v = Verifier(KEY)
    opened = v.open(K, payload)
    assert opened.body == b"body" and opened.signer is not None
    assert (opened.signer.name, opened.signer.role) == ("supervisor", Role.NODE)
    assert opened.signer.session == s._session
    replay = v.open(K, payload)
    assert replay.signer is None and replay.why == "replayed message"
    assert Verifier(KEY).open(K, s.sign(K, b"x", Role.OPERATOR)).signer.role == Role.OPERATOR


@pytest.mark.parametrize("case", ["unsigned", "other secret", "flipped", "other key",
                                  "truncated"])
def test_forgeries_do_not_open(case: str) -> None:
    s = Signing(KEY, "supervisor", Role.NODE)
    payload = s.sign(K, b"body")
    key, secret = K, KEY
    if case == "unsigned":
        payload = b"body"
    elif case == "other secret":
        secret = b"x" * 32
    elif case == "flipped":
        payload = bytes([payload[0] ^ 1]) + payload[1:]
    elif case == "other key":
        key = "mesp/sim/extruder/cmd"
    elif case == "truncated":
        payload = payload[:-10]
    opened = Verifier(secret).open(key, payload)
    assert opened.signer is None and opened.why


def test_a_stale_signature_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    s = Signing(KEY, "robot", Role.NODE)
    real = signing.time.time
    monkeypatch.setattr(signing.time, "time", lambda: real() - signing.WINDOW_S - 1)
    old = s.sign(K, b"body")
    monkeypatch.setattr(signing.time, "time", real)
    assert "stale" in Verifier(KEY).open(K, old).why


def test_out_of_order_counters_pass_once_within_the_window() -> None:
    s = Signing(KEY, "robot", Role.NODE)
    msgs = [s.sign(K, bytes([i])) for i in range(5)]
    v = Verifier(KEY)
    for i in (3, 0, 4, 1, 2):
        assert v.open(K, msgs[i]).signer is not None
    assert all(v.open(K, m).signer is None for m in msgs)


def test_split_leaves_plain_payloads_alone() -> None:
    assert split(b"plain") == (b"plain", b"")
    # ends with the magic but a length that cannot be a trailer
    fake = b"x" * 10 + struct.pack("<H4s", 60000, signing.MAGIC)
    assert split(fake) == (fake, b"")
