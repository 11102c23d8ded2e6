"""A lab balance on a serial line: the mass readings of the extrusion calibration."""

from __future__ import annotations

import re
from typing import Protocol

from core.errors import InputError


class Scale(Protocol):
    """A balance: one stable reading in g (``SerialScale``, ``EmulatedScale``)."""

    def grams(self) -> float: ...

    def close(self) -> None: ...


class SerialScale:
    """A balance on a serial line: sends ``W\\r\\n``, reads one line such as
    ``ST,GS    12.345 g`` (the first number and its unit; status prefixes are skipped).

    ``url`` is a pyserial URL or device (``/dev/ttyUSB0``, ``loop://``, a pty path).
    """

    def __init__(self, url: str, baudrate: int = 9600, timeout: float = 2.0) -> None:
        import serial

        self.port = serial.serial_for_url(url, baudrate=baudrate, timeout=timeout)

    def grams(self) -> float:
        """One stable reading in g (kg and mg are converted)."""
        self.port.reset_input_buffer()
        self.port.write(b"W\r\n")
        line = self.port.readline().decode(errors="replace").strip()
        m = re.search(r"([-+]?\d+(?:\.\d*)?)\s*(mg|kg|g)\b", line)
        if not m:
            raise InputError(f"the scale answered '{line}'", "check the scale's port and mode")
        value = float(m.group(1))
        return value * {"mg": 1e-3, "g": 1.0, "kg": 1e3}[m.group(2)]

    def close(self) -> None:
        self.port.close()
