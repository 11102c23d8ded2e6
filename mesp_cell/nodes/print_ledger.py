"""What the robot reported printed: an append-only ledger in the job's folder.

The robot node appends one record when a stream starts and one for every deposition waypoint
its servo loop passes, before it publishes the waypoint on the bus. The file outlives every
process (a killed supervisor, robot or a whole cell): the supervisor resumes right after the
ledger's last waypoint, and a job is done only when the ledger holds every deposition waypoint
exactly once. The robot's extruder switches on a fast twin add what their latency cost in
simulated time (``extruder_switch``). A record is 3 little-endian int64 written with one
``write`` on an
``O_APPEND`` descriptor (a killed process leaves whole records; a torn tail is ignored).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

NAME = "printed.ledger"
# record kinds: (WAYPOINT, id, sample), (STREAM, start, after), (STOP, last sample sent, 0),
# (SWITCH, excess ink in NANO mm^3, latency in NANO s)
WAYPOINT, STREAM, STOP, SWITCH = 0, 1, 2, 3
RECORD = np.dtype("<i8")
NANO = 1e-9  # unit of the SWITCH record's values


@dataclass(frozen=True)
class Printed:
    """A ledger read back.

    Attributes:
        waypoints: (n,) int64, waypoint ids in the order the robot passed them.
        samples: (n,) int64, servo sample of each.
        streams: (s, 2) int64, (start sample, after_waypoint) of each stream, in order.
        stream_at: (s,) int64, waypoints printed before each stream began.
        stop: the last sample the last stream sent if it stopped early and its process lived
            to say so (-1 otherwise).
        switch_mm3: nominal mm^3 the extruder switches' latency moved on a fast twin beyond
            real time (``extruder_switch``; 0 on the real cell).
        switches: switches recorded.
    """

    waypoints: np.ndarray
    samples: np.ndarray
    streams: np.ndarray
    stream_at: np.ndarray
    stop: int = -1
    switch_mm3: float = 0.0
    switches: int = 0

    @property
    def last(self) -> tuple[int, int]:
        """(waypoint, sample) of the last waypoint printed; (-1, -1) if none."""
        if not self.waypoints.size:
            return -1, -1
        return int(self.waypoints[-1]), int(self.samples[-1])

    @property
    def doubled(self) -> int:
        """Waypoints reported more than once (each extra report counts)."""
        return int(self.waypoints.size - np.unique(self.waypoints).size)

    def missing(self, expected: np.ndarray) -> np.ndarray:
        """(m,) int64: ids of ``expected`` never reported."""
        return np.setdiff1d(np.asarray(expected, dtype=np.int64), self.waypoints)

    def restreamed(self) -> int:
        """Printed waypoints a later stream went over again: it started at a sample before
        theirs, so the arm re-traced deposited path (a resume starts at the last one's)."""
        return sum(int(np.count_nonzero(self.samples[:n] > start))
                   for (start, _), n in zip(self.streams[1:], self.stream_at[1:], strict=True))


def read(job_dir: Path) -> Printed:
    """The ledger of ``job_dir`` (empty if there is none)."""
    path = Path(job_dir) / NAME
    raw = np.fromfile(path, dtype=RECORD) if path.is_file() else np.zeros(0, RECORD)
    rec = raw[: raw.size - raw.size % 3].reshape(-1, 3)
    sw = rec[:, 0] == SWITCH
    excess = float(rec[sw, 1].sum()) * NANO
    rec = rec[~sw]
    wp = rec[:, 0] == WAYPOINT
    st = rec[:, 0] == STREAM
    before = np.concatenate([[0], np.cumsum(wp)])[np.flatnonzero(st)].astype(np.int64)
    stop = -1
    if rec.size and rec[-1, 0] == STOP:
        stop = int(rec[-1, 1])
    return Printed(rec[wp, 1].copy(), rec[wp, 2].copy(), rec[st, 1:].copy(), before, stop,
                   excess, int(np.count_nonzero(sw)))


class Ledger:
    """The robot node's writer of one job's ledger (``fresh`` empties it first)."""

    def __init__(self, job_dir: Path, fresh: bool) -> None:
        path = Path(job_dir) / NAME
        flags = os.O_WRONLY | os.O_CREAT | os.O_APPEND | (os.O_TRUNC if fresh else 0)
        self.fd = os.open(path, flags, 0o600)

    def _write(self, kind: int, a: int, b: int) -> None:
        os.write(self.fd, np.array([kind, a, b], RECORD).tobytes())

    def stream(self, start: int, after_waypoint: int) -> None:
        self._write(STREAM, start, after_waypoint)

    def waypoint(self, waypoint: int, sample: int) -> None:
        self._write(WAYPOINT, waypoint, sample)

    def stopped(self, last_sample: int) -> None:
        """The stream stopped early after sending ``last_sample``."""
        self._write(STOP, last_sample, 0)

    def switch(self, excess_mm3: float, latency_s: float) -> None:
        """An extruder switch ``latency_s`` late moved ``excess_mm3`` (nominal) beyond real
        time."""
        self._write(SWITCH, round(excess_mm3 / NANO), round(latency_s / NANO))

    def close(self) -> None:
        os.close(self.fd)
