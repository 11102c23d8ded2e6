"""The bus: typed pub/sub, commands with replies, presence, refusal when nobody answers."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterator

import pytest

from core.errors import InputError
from mesp_cell.bus.session import Bus, BusConfig
from mesp_cell.bus.signing import Role
from mesp_cell.drivers.extruder_emulator import free_port
from mesp_cell.messages import Command, EStop, Heartbeat, Reply

KEY = b"k" * 32


@pytest.fixture
def pair() -> Iterator[tuple[Bus, Bus]]:
    hub = f"tcp/127.0.0.1:{free_port()}"
    a = Bus(BusConfig(cell="t", listen=(hub,)), "alpha", Role.NODE, KEY)
    b = Bus(BusConfig(cell="t", connect=(hub,)), "beta", Role.OPERATOR, KEY)
    yield a, b  # each test waits for the condition it needs (a subscriber, a server, a token)
    b.close()
    a.close()


def wait(event: threading.Event) -> bool:
    return event.wait(5.0)


def test_publish_subscribe_typed(pair: tuple[Bus, Bus]) -> None:
    a, b = pair  # a topic that waits for room (a periodic one may drop under congestion)
    got: list[Heartbeat] = []
    done = threading.Event()

    def on(msg: Heartbeat) -> None:
        got.append(msg)
        if len(got) == 3:
            done.set()

    assert not a.wait_subscribed("typed", timeout=0.1)
    b.subscribe("alpha", "typed", Heartbeat, on)
    assert a.wait_subscribed("typed")
    a.publish("typed", EStop("x", "wrong type on this topic", 0.0))
    for i in range(3):
        a.publish("typed", Heartbeat("alpha", "active", i, 1, float(i)))
    assert wait(done)
    assert [m.seq for m in got] == [0, 1, 2]
    assert b.dropped == 1


def test_request_reply_and_refusals(pair: tuple[Bus, Bus],
                                    monkeypatch: pytest.MonkeyPatch) -> None:
    a, b = pair
    # pytest's log capture is slow to take a traceback from zenoh's callback thread.
    monkeypatch.setattr(logging.getLogger("mesp.bus"), "disabled", True)

    def handler(cmd: Command) -> Reply:
        if cmd.verb == "bad":
            raise InputError("bad input", "fix it")
        if cmd.verb == "bug":
            raise RuntimeError("boom")
        return Reply.done(echo=cmd.arg("x"))

    assert not b.wait_served("alpha", timeout=0.1)
    a.serve(handler)
    assert b.wait_served("alpha")
    assert b.request("alpha", Command.make("ok", x=3)).value("echo") == 3
    assert b.request("alpha", Command.make("bad")).reason == "bad input; fix it"
    assert "boom" in b.request("alpha", Command.make("bug")).reason
    nobody = b.request("gamma", Command.make("ok"), timeout=0.3)
    assert not nobody.ok and "no reply from node 'gamma'" in nobody.reason


def test_presence_follows_the_session(pair: tuple[Bus, Bus]) -> None:
    a, b = pair
    events: list[tuple[str, bool]] = []
    gone = threading.Event()

    def on(node: str, alive: bool) -> None:
        events.append((node, alive))
        if node == "alpha" and not alive:
            gone.set()

    a.announce()
    b.watch_presence(on)
    end = time.monotonic() + 10
    while "alpha" not in b.alive_nodes(0.5) and time.monotonic() < end:
        time.sleep(0.02)
    assert "alpha" in b.alive_nodes(1.0)
    seq = 0  # the token alone is not presence: alpha beats (signed) as a node does
    while ("alpha", True) not in events and time.monotonic() < end:
        seq += 1
        a.publish("heartbeat", Heartbeat("alpha", "active", seq, 1, time.time()))
        time.sleep(0.05)
    a.close()
    assert wait(gone)
    assert ("alpha", True) in events and events[-1] == ("alpha", False)


def test_config_validation() -> None:
    with pytest.raises(InputError):
        BusConfig(cell="Bad Cell")
    with pytest.raises(InputError):
        BusConfig(connect=("127.0.0.1",))
    cfg = BusConfig(cell="c", connect=("tcp/127.0.0.1:1",))
    assert BusConfig.from_json(cfg.to_json()) == cfg
