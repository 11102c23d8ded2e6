"""The extruder rate that follows the arm's planned speed during a stream.

Where the planner slows the arm below the toolpath's speed, a constant rate would pile up ink.
``FlowSync`` commands the set-point times ``StreamPlan.flow_at`` of the step the nozzle will be
on when the screw has followed (``lead_n`` samples ahead), so the ink per millimetre stays the
slicer's. Small changes are not sent, and commands are spaced, to spare the bus and the Modbus
link.
"""

from __future__ import annotations

from mesp_cell.drivers.stream import StreamPlan

FLOW_STEP = 0.03  # a rate change smaller than this x the set-point is not sent
FLOW_INTERVAL_S = 0.02  # s of wall time between two rate commands, at least (bus, Modbus)


class FlowSync:
    """The rate commands of one stream that keep the ink per millimetre where the arm is
    slower than the toolpath: at servo sample k, the set-point ``rate`` x
    ``plan.flow_at(k + lead_n)`` (the step
    the nozzle will be on when the screw has followed), sent when it differs from the last
    sent by more than FLOW_STEP x ``rate`` and ``interval_n`` samples have passed since."""

    def __init__(self, plan: StreamPlan, rate: float, lead_n: int, end: int, interval_n: int,
                 start: int) -> None:
        self.plan, self.rate, self.lead_n, self.end = plan, rate, lead_n, end
        self.interval_n = max(int(interval_n), 1)
        self.sent = rate  # the supervisor starts the extruder at the job's set-point
        self.sent_k = start - self.interval_n

    def _target(self, k: int) -> float:
        return self.rate * self.plan.flow_at(min(k + self.lead_n, self.end - 1))

    def switch_on(self, k: int) -> float:
        """The rate to start the extruder at, at sample ``k``."""
        self.sent, self.sent_k = self._target(k), k
        return self.sent

    def __call__(self, k: int) -> float | None:
        """The rate to command at sample ``k`` while depositing, None to keep the last."""
        if k - self.sent_k < self.interval_n:
            return None
        target = self._target(k)
        if abs(target - self.sent) <= FLOW_STEP * self.rate:
            return None
        self.sent, self.sent_k = target, k
        return target
