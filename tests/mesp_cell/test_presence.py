"""Presence that cannot be forged: a token without signed heartbeats is not a node; a forged
token does not keep a dead node present; a restarted node is reported gone, then back."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator

import pytest

from mesp_cell.bus.presence import PresenceWatch
from mesp_cell.bus.session import Bus, BusConfig
from mesp_cell.bus.signing import Role
from mesp_cell.drivers.extruder_emulator import free_port
from mesp_cell.messages import Heartbeat

KEY = b"p" * 32


class Events:
    def __init__(self) -> None:
        self.seen: list[tuple[str, bool, float]] = []
        self.lock = threading.Lock()

    def __call__(self, node: str, alive: bool) -> None:
        with self.lock:
            self.seen.append((node, alive, time.monotonic()))

    def wait(self, node: str, alive: bool, timeout: float = 10.0,
             after: float = -1.0) -> float | None:
        """When ``node`` was last reported ``alive`` (later than ``after``), waiting
        ``timeout`` s at most; None if it was not."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            with self.lock:
                hits = [t for n, a, t in self.seen if (n, a) == (node, alive) and t > after]
            if hits:
                return hits[-1]
            time.sleep(0.02)
        return None


def wait_for(predicate: Callable[[], bool], timeout: float = 10.0) -> bool:
    """Whether ``predicate`` became true within ``timeout`` s."""
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() >= end:
            return False
        time.sleep(0.02)
    return True


@pytest.fixture
def hub() -> Iterator[tuple[str, Bus]]:
    ep = f"tcp/127.0.0.1:{free_port()}"
    watcher = Bus(BusConfig(cell="t", listen=(ep,)), "watcher", Role.NODE, KEY)
    yield ep, watcher
    watcher.close()


def node(ep: str, name: str, secret: bytes | None) -> Bus:
    return Bus(BusConfig(cell="t", connect=(ep,)), name, Role.NODE, secret)


def beat(bus: Bus, stop: threading.Event) -> threading.Thread:
    def run() -> None:
        i = 0
        while not stop.wait(0.1):
            i += 1
            bus.publish("heartbeat", Heartbeat(bus.node, "active", i, 1, time.time()))

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


def test_a_forged_token_is_not_presence_and_does_not_outlive_the_node(
        hub: tuple[str, Bus]) -> None:
    ep, watcher = hub
    events = Events()
    watch = PresenceWatch(watcher, events, timeout_s=1.0)
    fake = node(ep, "alpha", None)  # the name and a token, no secret
    fake.announce()
    stop = threading.Event()
    fake_beats = beat(fake, stop)
    # its token and its unsigned beats reach the watcher, and are not presence
    assert wait_for(lambda: "alpha" in watch.tokens and watcher.refused >= 3)
    assert events.wait("alpha", True, 0.5) is None
    real = node(ep, "alpha", KEY)
    real_stop = threading.Event()
    beater = beat(real, real_stop)
    real.announce()
    assert events.wait("alpha", True) is not None
    t_kill = time.monotonic()
    real_stop.set()
    beater.join()
    real.close()  # its token goes, the forged one stays: the missing beats end presence
    gone = events.wait("alpha", False)
    assert gone is not None and gone - t_kill < 1.0 + 0.5
    stop.set()
    fake_beats.join()
    fake.close()


def test_a_restarted_node_is_gone_then_back(hub: tuple[str, Bus]) -> None:
    ep, watcher = hub
    events = Events()
    # a timeout no loaded host reaches in this test: only the restart can end the presence
    PresenceWatch(watcher, events, timeout_s=60.0)
    stop = threading.Event()
    fake = node(ep, "alpha", None)
    fake.announce()  # holds the token across the restart
    first = node(ep, "alpha", KEY)
    beater = beat(first, stop)
    first.announce()
    assert events.wait("alpha", True) is not None
    stop.set()
    beater.join()
    first.close()
    stop2 = threading.Event()
    second = node(ep, "alpha", KEY)  # a new session of the same name
    beater = beat(second, stop2)
    second.announce()
    gone = events.wait("alpha", False)  # well before the 60 s timeout
    assert gone is not None
    assert events.wait("alpha", True, after=gone) is not None  # and back
    with events.lock:
        assert events.seen[-1][:2] == ("alpha", True)
    stop2.set()
    beater.join()
    second.close()
    fake.close()
