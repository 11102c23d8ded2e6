"""The time left of a print, from the pace its stream keeps."""

from __future__ import annotations

from collections import deque


class EtaEstimate:
    """Time left from the pace the stream keeps, not the pace it was asked for.

    A twin that cannot keep its time scale (MuJoCo at 80x on 2 cores ran at ~64x) would make
    ``remaining x dt / time_scale`` promise too early an end. The pace is measured over the
    last ``WINDOW_S`` of wall time, once at least ``MIN_SPAN_S`` of it is seen; before that,
    and while no sample advances, the nominal pace stands.

    Args:
        nominal: samples per wall second asked for (``time_scale / dt``).
    """

    WINDOW_S = 30.0
    MIN_SPAN_S = 2.0

    def __init__(self, nominal: float) -> None:
        self.nominal = nominal
        self._seen: deque[tuple[float, int]] = deque()

    def __call__(self, now: float, sample: int, remaining: int) -> float:
        """Seconds of wall time left, with ``sample`` reached at ``now`` (monotonic s)."""
        seen = self._seen
        seen.append((now, sample))
        while len(seen) > 2 and now - seen[1][0] >= self.WINDOW_S:
            seen.popleft()
        t0, s0 = seen[0]
        pace = self.nominal
        if now - t0 >= self.MIN_SPAN_S and sample > s0:
            pace = (sample - s0) / (now - t0)
        return max(remaining, 0) / pace
