"""The ink a print extrudes that is not the toolpath's: the screw turning with the nozzle at rest.

The screw runs ``lead_s`` ahead of the arm, so a stream's screw time is its deposition time
plus the time it ran at rest before the stream (purge, lead, until the robot took the stream),
less the deposition in the lead after its first sample (the lead paid back), plus, when it
stops early, the deposition in the lead after the stop; a resume re-traces from the last
printed waypoint to the stop. The supervisor adds each to the job's ``report.json``
(``ink_at_rest``) as it happens, so the sum outlives a killed supervisor; the print check
takes it off the totaliser's ink (``print_check``).

The time at rest is counted on the clock the extruder's flow runs on (``RestTimer``): on the
twin its shared simulated clock (``sim_clock``), which stands still while the twin lags or a
switch holds it; on the real cell the wall clock.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from core.report import read_report, update_report
from mesp_cell.drivers.sim_clock import SimClock
from mesp_cell.drivers.stream import StreamPlan


def rest_ink(job_dir: Path) -> float:
    """mm^3 of the job's ink that is not the toolpath's, so far."""
    return float(read_report(Path(job_dir)).get("ink_at_rest", {}).get("mm3", 0.0))


def add_rest_ink(job_dir: Path, mm3: float) -> None:
    """Add ``mm3`` to the job's ink at rest (``rest_ink``)."""
    update_report(Path(job_dir), {"ink_at_rest": {"mm3": rest_ink(job_dir) + mm3}})


def deposition_s(plan: StreamPlan, k: int, lead_s: float, stop: int | None = None) -> float:
    """s of deposition after servo sample ``k`` up to ``lead_s`` past ``stop`` (default
    ``k``): the screw runs that far ahead of the arm (the robot switches it ``lead_s``
    ahead)."""
    last = k if stop is None else stop
    idx = np.arange(k + 1, min(last + 1 + round(lead_s / plan.dt), plan.samples))
    return float(np.count_nonzero(plan.extrude[idx])) * plan.dt if idx.size else 0.0


class RestTimer:
    """Seconds of the extruder's flow clock since ``start``: the twin's shared simulated
    clock when ``clock`` is given, else the wall clock times ``time_scale`` (the real cell:
    1; a twin without a shared clock runs its extruder on a private clock that fast)."""

    def __init__(self, clock: SimClock | None, time_scale: float) -> None:
        self.clock, self.time_scale = clock, time_scale
        self.t0 = self._now()

    def _now(self) -> float:
        if self.clock is not None:
            return self.clock.now()
        return time.monotonic() * self.time_scale

    def seconds(self) -> float:
        """s of the flow's clock since the timer was made (never negative: a shared clock
        can appear to step back, ``sim_clock``)."""
        return max(0.0, self._now() - self.t0)
