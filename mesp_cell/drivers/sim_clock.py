"""The simulated cell's clock, shared by the robot twin and the emulated extruder.

On the twin, simulated time runs ``scale`` times faster than the wall clock:
``sim = min(scale * (wall - paused), hold)``, where ``wall`` is ``time.monotonic()``
(system-wide on Linux, so two processes read the same wall), ``paused`` is the wall time during
which simulated time stood still, and ``hold`` the simulated time the clock may not pass now.
Only the robot process writes them (the twin's servo thread and its extruder switches): when
the twin's servo loop cannot keep the asked pace (MuJoCo on a loaded 2-core host at 80x),
simulated time waits for the arm, and the extruder's flow, which integrates over the same
clock, waits with it. Without that, the emulated extruder ran on its own scaled clock and kept
flowing while the arm lagged: +4.2% of ink on the socket at 80x, 2.9 times the toolpath's
volume on the hemisphere at 200x.

Why a hold as well as the pause: a twin learns it lagged only once it runs again, so a pause
alone comes after its readers counted the lag. The emulated extruder flowed on through a stalled
twin with the state it had (a screw off between layers stayed off), then stood still while the
twin caught up and switched it (the screw came on late): the ink of the stall moved from one
side of the switch to the other (docs/robustness.md). So during a
motion the twin holds the clock at the simulated time it has reached, every period, and each
extruder switch holds it at the time it was decided until the extruder took it: a reader never
sees a time the twin or a switch has not reached. A hold lapses ``hold_s`` wall seconds after
it was set (a killed twin does not stop the clock for good; a stall that long trips the servo
watchdog anyway).

Between processes the clock lives in a 56-byte file (``path``, mapped in memory): a sequence
number and two slots of (``paused`` s, ``hold`` simulated s, the wall s the hold lapses at),
float64. The writer puts each new value into the
slot the current sequence does not point at, then publishes it by storing the next sequence
number (one aligned 8-byte store). A reader takes the sequence, the slot it points at and the
sequence again: unchanged, the value is whole (the writer only ever fills the other slot);
changed (a value was published during the read, which takes under a microsecond), it reads
again. So a reader never sees a torn value and never waits for a writer, even one stopped or
killed in the middle of a write: the published slot stays whole. (Store and load order as on
x86-64, where the cell runs: Python cannot place memory barriers.) Writers in the robot
process take a lock, so the file has one writer at a time. Without a path the clock is private
to one process.
"""

from __future__ import annotations

import math
import mmap
import os
import struct
import threading
import time
from pathlib import Path

from core.tolerance import tol

_SIZE = 8 + 2 * 3 * 8  # the sequence (uint64), then two slots of (paused, hold, until)
_SLOT = 3  # float64 values per slot: paused (wall s), hold (simulated s), until (wall s)
_PACK = struct.Struct("=3d")  # one slot, as the float64 view reads it
READ_TRIES = 1000  # a reader retries only when a value was published during its read


class SimClock:
    """Simulated time ``min(scale * (wall - paused), hold)``, s.

    Args:
        scale: simulated seconds per wall second (the launch's ``time_scale``), > 0.
        path: the shared file; None keeps the clock in this process.
        reset: start the shared clock at ``paused = 0`` and no hold (the process that owns
            the file, the extruder emulator, which the launch starts first); False attaches to
            it as it is (the twin, which may restart within a launch and must not rewind the
            clock).
    """

    def __init__(self, scale: float, path: str | Path | None = None, reset: bool = False) -> None:
        if not scale > 0:
            raise ValueError(f"time scale {scale} must be > 0")
        self.scale = float(scale)
        self.path = Path(path) if path else None
        self._paused = 0.0
        self._holds: dict[str, tuple[float, float]] = {}  # key -> (simulated s, lapses at)
        self._published = (0.0, 0.0, 0.0)  # (paused, hold, until) of a private clock
        self._write_lock = threading.Lock()
        self._map: mmap.mmap | None = None
        self._seq: memoryview[int] | None = None  # the sequence, uint64
        self._val: memoryview[float] | None = None  # the two slots, float64 (reads)
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o600)
            try:
                if reset or os.fstat(fd).st_size != _SIZE:
                    os.ftruncate(fd, 0)
                    os.ftruncate(fd, _SIZE)  # zeros: sequence 0, paused 0.0, no hold
                self._map = mmap.mmap(fd, _SIZE)
            finally:
                os.close(fd)
            self._seq = memoryview(self._map)[:8].cast("Q")
            self._val = memoryview(self._map)[8:].cast("d")
            self._paused = self.paused()

    @staticmethod
    def wall() -> float:
        """The wall clock the simulated time is counted on, s (``time.monotonic``)."""
        return time.monotonic()

    def _read(self) -> tuple[float, float, float]:
        """(paused, hold, until): a whole published value (see above)."""
        seq, val = self._seq, self._val
        if seq is None or val is None:
            return self._published
        for _ in range(READ_TRIES):
            n = seq[0]
            i = _SLOT * (n & 1)
            value = (val[i], val[i + 1], val[i + 2])
            if seq[0] == n:
                return value
        i = _SLOT * (seq[0] & 1)  # the writer publishing non-stop: its latest
        return val[i], val[i + 1], val[i + 2]

    def paused(self) -> float:
        """Wall seconds during which simulated time stood still (a whole value, see above)."""
        return self._read()[0]

    def now(self, wall: float | None = None) -> float:
        """Simulated time at ``wall`` (default: now), s: never past a hold in force."""
        w = self.wall() if wall is None else wall
        paused, hold, until = self._read()
        free = self.scale * (w - paused)
        return min(free, hold) if w < until else free

    def wall_at(self, sim: float) -> float:
        """The wall time at which simulated time reaches ``sim`` (if it does not pause), s."""
        return sim / self.scale + self.paused()

    def pause(self, wall_s: float) -> None:
        """Hold simulated time for ``wall_s`` more wall seconds (the writer's side)."""
        if not wall_s > 0:  # nor NaN: the clock never runs forward or breaks
            return
        with self._write_lock:
            self._paused += wall_s
            self._publish()

    def hold(self, key: str, sim: float, hold_s: float, pause_s: float = 0.0) -> None:
        """Let no reader see simulated time past ``sim`` until ``release(key)`` or for
        ``hold_s`` wall seconds (the writer's side; holds of other keys stay, the earliest
        one is in force); with ``pause_s`` > 0, also pause for that long, in the same
        publication."""
        with self._write_lock:
            if pause_s > 0:
                self._paused += pause_s
            if math.isfinite(sim) and hold_s > 0:
                self._holds[key] = (float(sim), self.wall() + hold_s)
            else:
                self._holds.pop(key, None)
            self._publish()

    def release(self, key: str) -> None:
        """Lift the hold ``key`` (the writer's side; nothing if it holds nothing)."""
        with self._write_lock:
            if self._holds.pop(key, None) is not None:
                self._publish()

    def _publish(self) -> None:
        """Make ``paused`` and the earliest hold the readers' value (under the write lock)."""
        hold, until = min(self._holds.values(), default=(0.0, 0.0))
        seq, mapped = self._seq, self._map
        if seq is None or mapped is None:
            self._published = (self._paused, hold, until)
            return
        n = seq[0]
        at = 8 + 8 * _SLOT * ((n + 1) & 1)  # the slot readers are not pointed at
        mapped[at : at + 8 * _SLOT] = _PACK.pack(self._paused, hold, until)
        seq[0] = n + 1  # publish: one aligned 8-byte store

    def close(self) -> None:
        for view in (self._seq, self._val):  # the views hold the buffer: release them first
            if view is not None:
                view.release()
        self._seq = self._val = None
        if self._map is not None:
            self._map.close()
            self._map = None


def clock_for(scale: float, clock: SimClock | None = None) -> SimClock:
    """``clock``, checked to run at ``scale`` (a clock of another speed is a launch mistake),
    or a private clock at ``scale``."""
    if clock is None:
        return SimClock(scale)
    if abs(clock.scale - scale) > tol.slack * scale:
        raise ValueError(f"clock scale {clock.scale} differs from time_scale {scale}")
    return clock
