"""How often a node's state loop runs: its full rate while the cell moves or extrudes, a slow
idle rate while it rests, and the full rate again the moment that changes.

The robot and extruder nodes publish their states at ``state_hz`` for the interlocks that
judge them (the robot's extruder staleness and flow check while it deposits, the extruder's
robot staleness while the screw runs); a resting cell needs none of that, and every state
wakes each subscriber's process. A node is *busy* while it or its peer moves, extrudes or (the
extruder) shows a fault; the peer's state that makes it busy wakes its loop at once
(``Pace.wake``), so the full rate is back before any motion or extrusion relies on it.

The only judge that can meet an idle-paced state is the extruder's robot staleness, in the
moment between the screw's start and the robot's first state after it heard of it: it counts
from the start (``ExtruderNode._robot_stale``). The idle rate is owned here.
"""

from __future__ import annotations

import threading
import time

#: States per second of a node at rest (nothing moves, nothing extrudes).
IDLE_HZ = 10.0


class Pace:
    """The schedule of one state loop. ``hz``: the full rate; ``idle_hz``: the rate at rest
    (never above ``hz``)."""

    def __init__(self, hz: float, idle_hz: float = IDLE_HZ) -> None:
        if not (hz > 0 and idle_hz > 0):
            raise ValueError(f"state rates must be > 0 (state_hz {hz}, idle {idle_hz})")
        self.period = 1.0 / hz
        self.idle_period = max(self.period, 1.0 / idle_hz)
        self._wake = threading.Event()

    def wake(self) -> None:
        """End a wait now: the cell is about to move or extrude (thread-safe)."""
        self._wake.set()

    def begin(self) -> None:
        """Call at the top of each iteration, before reading what decides ``busy``: a wake
        that comes after it ends the next wait (none is lost)."""
        self._wake.clear()

    def period_for(self, busy: bool) -> float:
        """s between states: the full period while busy, the idle period at rest."""
        return self.period if busy else self.idle_period

    def wait(self, next_t: float, busy: bool, now: float) -> float:
        """Sleep until the next state is due and return when that is (monotonic s).

        Busy: ``next_t`` plus a period, or a period from ``now`` when late (no burst). At
        rest: an idle period from ``now``. A ``wake`` ends the wait at once.
        """
        if busy:
            due = next_t + self.period
            if due < now:
                due = now + self.period
        else:
            due = now + self.idle_period
        if self._wake.wait(max(0.0, due - time.monotonic())):
            return time.monotonic()
        return due

