"""What every extruder driver provides: one reading type, one error type, one interface."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol


class ExtruderLinkError(RuntimeError):
    """The link to the extruder controller failed and the retries are used up."""


@dataclass(frozen=True)
class ExtruderReading:
    """One read of the controller.

    Attributes:
        rate_set: mm^3/s, set-point the host last wrote. rate: mm^3/s, measured.
        volume: mm^3, totaliser. running: motor on. fault: fault bits (messages.FAULT_*).
        ctrl_heartbeat: controller cycle counter (u16).
    """

    rate_set: float
    rate: float
    volume: float
    running: bool
    fault: int
    ctrl_heartbeat: int


class ExtruderDriver(Protocol):
    """A volumetric extruder: set-point in mm^3/s, run/stop, read-back, host heartbeat."""

    def connect(self) -> None: ...

    def close(self) -> None: ...

    def start(self, rate: float) -> None: ...

    def set_rate(self, rate: float) -> None: ...

    def stop(self) -> None: ...

    def estop(self) -> None: ...

    def reset(self) -> None: ...

    def heartbeat(self) -> None: ...

    def read(self) -> ExtruderReading: ...
