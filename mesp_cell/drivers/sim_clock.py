"""The simulated cell's clock, shared by the robot twin and the emulated extruder.

On the twin, simulated time runs ``scale`` times faster than the wall clock:
``sim = scale * (wall - paused)``, where ``wall`` is ``time.monotonic()`` (system-wide on Linux,
so two processes read the same wall) and ``paused`` is the wall time during which simulated
time stood still. Only the twin writes ``paused``: when its servo loop cannot keep the asked
pace (MuJoCo on a loaded 2-core host at 80x), simulated time waits for the arm, and the
extruder's flow, which integrates over the same clock, waits with it. Without that, the
emulated extruder ran on its own scaled clock and kept flowing while the arm lagged: +4.2% of
ink on the socket at 80x, 2.9 times the toolpath's volume on the hemisphere at 200x.

Between processes the clock lives in a 16-byte file (``path``, mapped in memory): a sequence
number and ``paused`` (float64, s). The writer makes the sequence odd while it writes, so a
reader never sees a torn value (a seqlock). Without a path the clock is private to one process.
"""

from __future__ import annotations

import mmap
import os
import struct
import time
from pathlib import Path

_LAYOUT = struct.Struct("<Qd")  # sequence, paused (s)
READ_TRIES = 10_000  # a write takes well under a microsecond


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
        self._seq = 0
        self._map: mmap.mmap | None = None
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                if reset or os.fstat(fd).st_size < _LAYOUT.size:
                    os.ftruncate(fd, 0)
                    os.ftruncate(fd, _LAYOUT.size)  # zeros: sequence 0, paused 0.0
                self._map = mmap.mmap(fd, _LAYOUT.size)
            finally:
                os.close(fd)
            self._seq, self._paused = _LAYOUT.unpack_from(self._map, 0)

    @staticmethod
    def wall() -> float:
        """The wall clock the simulated time is counted on, s (``time.monotonic``)."""
        return time.monotonic()

    def paused(self) -> float:
        """Wall seconds during which simulated time stood still."""
        if self._map is None:
            return self._paused
        for _ in range(READ_TRIES):
            seq, paused = _LAYOUT.unpack_from(self._map, 0)
            if seq & 1 == 0 and _LAYOUT.unpack_from(self._map, 0)[0] == seq:
                return float(paused)
        # a writer killed in the middle of a write leaves the sequence odd: its value stands
        return float(paused)

    def now(self, wall: float | None = None) -> float:
        """Simulated time at ``wall`` (default: now), s."""
        return self.scale * ((self.wall() if wall is None else wall) - self.paused())

    def wall_at(self, sim: float) -> float:
        """The wall time at which simulated time reaches ``sim`` (if it does not pause), s."""
        return sim / self.scale + self.paused()

    def pause(self, wall_s: float) -> None:
        """Hold simulated time for ``wall_s`` more wall seconds (the writer's side)."""
        if wall_s <= 0:
            return
        self._paused += wall_s
        if self._map is None:
            return
        self._seq += 1
        struct.pack_into("<Q", self._map, 0, self._seq)  # odd: a write in progress
        struct.pack_into("<d", self._map, 8, self._paused)
        self._seq += 1
        struct.pack_into("<Q", self._map, 0, self._seq)

    def close(self) -> None:
        if self._map is not None:
            self._map.close()
            self._map = None


def clock_for(scale: float, clock: SimClock | None = None) -> SimClock:
    """``clock``, checked to run at ``scale`` (a clock of another speed is a launch mistake),
    or a private clock at ``scale``."""
    if clock is None:
        return SimClock(scale)
    if abs(clock.scale - scale) > 1e-9 * scale:
        raise ValueError(f"clock scale {clock.scale} differs from time_scale {scale}")
    return clock
