"""The simulated cell's clock, shared by the robot twin and the emulated extruder.

On the twin, simulated time runs ``scale`` times faster than the wall clock:
``sim = scale * (wall - paused)``, where ``wall`` is ``time.monotonic()`` (system-wide on Linux,
so two processes read the same wall) and ``paused`` is the wall time during which simulated
time stood still. Only the twin writes ``paused``: when its servo loop cannot keep the asked
pace (MuJoCo on a loaded 2-core host at 80x), simulated time waits for the arm, and the
extruder's flow, which integrates over the same clock, waits with it. Without that, the
emulated extruder ran on its own scaled clock and kept flowing while the arm lagged: +4.2% of
ink on the socket at 80x, 2.9 times the toolpath's volume on the hemisphere at 200x.

Between processes the clock lives in a 24-byte file (``path``, mapped in memory): a sequence
number and two slots of ``paused`` (float64, s). The one writer puts each new value into the
slot the current sequence does not point at, then publishes it by storing the next sequence
number (one aligned 8-byte store). A reader takes the sequence, the slot it points at and the
sequence again: unchanged, the value is whole (the writer only ever fills the other slot);
changed (a value was published during the read, which takes under a microsecond), it reads
again. So a reader never sees a torn value and never waits for a writer, even one stopped or
killed in the middle of a write: the published slot stays whole. (Store and load order as on
x86-64, where the cell runs: Python cannot place memory barriers.) Without a path the clock
is private to one process.
"""

from __future__ import annotations

import ctypes
import mmap
import os
import time
from pathlib import Path

from core.tolerance import tol


class _Shared(ctypes.Structure):
    """The file's layout: the sequence, then the two slots of ``paused`` (s)."""

    _fields_ = [("seq", ctypes.c_uint64), ("slot", ctypes.c_double * 2)]


_SIZE = ctypes.sizeof(_Shared)
READ_TRIES = 1000  # a reader retries only when a value was published during its read


class SimClock:
    """Simulated time ``scale * (wall - paused)``, s.

    Args:
        scale: simulated seconds per wall second (the launch's ``time_scale``), > 0.
        path: the shared file; None keeps the clock in this process.
        reset: start the shared clock at ``paused = 0`` (the process that owns the file, the
            extruder emulator, which the launch starts first); False attaches to it as it is
            (the twin, which may restart within a launch and must not rewind the clock).
    """

    def __init__(self, scale: float, path: str | Path | None = None, reset: bool = False) -> None:
        if not scale > 0:
            raise ValueError(f"time scale {scale} must be > 0")
        self.scale = float(scale)
        self.path = Path(path) if path else None
        self._paused = 0.0
        self._map: mmap.mmap | None = None
        self._shared: _Shared | None = None
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o600)
            try:
                if reset or os.fstat(fd).st_size != _SIZE:
                    os.ftruncate(fd, 0)
                    os.ftruncate(fd, _SIZE)  # zeros: sequence 0, paused 0.0
                self._map = mmap.mmap(fd, _SIZE)
            finally:
                os.close(fd)
            self._shared = _Shared.from_buffer(self._map)
            self._paused = self.paused()

    @staticmethod
    def wall() -> float:
        """The wall clock the simulated time is counted on, s (``time.monotonic``)."""
        return time.monotonic()

    def paused(self) -> float:
        """Wall seconds during which simulated time stood still (a whole value, see above)."""
        shared = self._shared
        if shared is None:
            return self._paused
        for _ in range(READ_TRIES):
            seq = shared.seq
            value = shared.slot[seq & 1]
            if shared.seq == seq:
                return float(value)
        return float(shared.slot[shared.seq & 1])  # the writer publishing non-stop: its latest

    def now(self, wall: float | None = None) -> float:
        """Simulated time at ``wall`` (default: now), s."""
        return self.scale * ((self.wall() if wall is None else wall) - self.paused())

    def wall_at(self, sim: float) -> float:
        """The wall time at which simulated time reaches ``sim`` (if it does not pause), s."""
        return sim / self.scale + self.paused()

    def pause(self, wall_s: float) -> None:
        """Hold simulated time for ``wall_s`` more wall seconds (the writer's side)."""
        if not wall_s > 0:  # nor NaN: the clock never runs forward or breaks
            return
        self._paused += wall_s
        shared = self._shared
        if shared is None:
            return
        seq = shared.seq
        shared.slot[(seq + 1) & 1] = self._paused  # the slot readers are not pointed at
        shared.seq = seq + 1  # publish: one aligned 8-byte store

    def close(self) -> None:
        self._shared = None  # the structure holds the buffer: release it before the map
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
