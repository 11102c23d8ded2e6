"""Measured flow against the commanded rate: the robot node's check that ink really comes.

The extruder's "running" flag says the motor was told to run, not that the screw turns at the
set-point (a stalled screw, a slipping coupling, a controller that ignores a set-point). Every
extruder state carries the rate the host commanded (``rate_set``) and the controller's measured
rate (``rate``). After a step of the set-point the measured rate follows the screw's
first-order response (time constant ``tau_s``) and is within the controller's accuracy band
``band`` of the new set-point after ``tau_s ln(1/band)``; until then it lies between the old and
the new set-point. So the check keeps the set-points of the last ``settle_s`` (that response
time on the wall clock, plus the command latency) and calls a mismatch when the measured rate
leaves [min (1 - band), max (1 + band)] of them by more than ``band`` x the largest set-point
of the stream, in two states in a row (one reading is not a fault).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from mesp_cell.drivers.registers import AT_SET_BAND
from mesp_cell.messages import ExtruderState

#: consecutive states outside the band that make a mismatch
PERSIST = 2


@dataclass(frozen=True)
class FlowResponse:
    """How the extruder's measured rate follows its set-point.

    Attributes:
        tau_s: s of the extruder's clock (the twin's simulated time), the screw's flow time
            constant (the launch's ``flow_tau_s``; the emulator's ``--tau``).
        band: relative accuracy of the measured rate: the controller's "at set-point" band
            (``registers.AT_SET_BAND``).
        time_scale: how much faster than real time the extruder's clock runs (1 on the cell).
        latency_s: s of wall time from a command to the state that shows it (bus, Modbus).
    """

    tau_s: float
    band: float = AT_SET_BAND
    time_scale: float = 1.0
    latency_s: float = 0.1

    def __post_init__(self) -> None:
        if not (self.tau_s > 0 and 0 < self.band < 1 and self.time_scale > 0
                and self.latency_s >= 0):
            raise ValueError("flow response: tau_s > 0, 0 < band < 1, time_scale > 0, "
                             "latency_s >= 0")

    @property
    def settle_s(self) -> float:
        """Wall s after a set-point step until the measured rate is within the band."""
        return self.tau_s * math.log(1.0 / self.band) / self.time_scale + self.latency_s


class FlowCheck:
    """Feed it every extruder state (``update``); ``mismatch`` says why the measured flow is
    not what was commanded ("" when it is)."""

    def __init__(self, response: FlowResponse) -> None:
        self.response = response
        self._targets: deque[tuple[float, float]] = deque()  # (monotonic s, set-point in force)
        self._peak = 0.0  # mm^3/s, the largest set-point seen
        self._bad = 0
        self._reason = ""

    def update(self, now: float, msg: ExtruderState) -> None:
        """An extruder state received at ``now`` (monotonic s)."""
        target = msg.rate_set if msg.running and not msg.fault else 0.0
        if not math.isfinite(target) or target < 0:
            target = 0.0
        q = self._targets
        if not q or q[-1][1] != target:
            q.append((now, target))
        # keep the set-point in force at the window's start
        while len(q) > 1 and q[1][0] <= now - self.response.settle_s:
            q.popleft()
        self._peak = max(self._peak, target)
        lo = min(t for _, t in q)
        hi = max(t for _, t in q)
        slack = self.response.band * self._peak
        band = self.response.band
        rate = msg.rate if math.isfinite(msg.rate) else -1.0
        if lo * (1 - band) - slack <= rate <= hi * (1 + band) + slack:
            self._bad, self._reason = 0, ""
            return
        self._bad += 1
        if self._bad >= PERSIST:
            self._reason = (f"measured flow {rate:.3g} mm^3/s outside the commanded "
                            f"{lo:.3g}-{hi:.3g} mm^3/s (+-{100 * band:.0f} % + "
                            f"{slack:.2g} mm^3/s, after {self.response.settle_s * 1000:.0f} ms "
                            "to follow a change)")

    def mismatch(self) -> str:
        """Why the measured flow disagrees with the commanded rate ("" if it agrees)."""
        return self._reason
