"""Extruder driver over a serial line (pyserial), an ASCII line protocol.

Host -> controller, one command per line (``\\n``); the controller answers one line:

    RUN <rate>      run at <rate> mm^3/s          -> OK
    RATE <rate>     change the set-point          -> OK
    STOP            motor off                     -> OK
    ESTOP           emergency stop (latched)      -> OK
    RESET           clear latched faults          -> OK
    HB <n>          host heartbeat (watchdog)     -> OK
    STAT?           -> STAT <running 0|1> <rate_set> <rate> <volume mm^3> <fault bits> <ctrl hb>
    anything else   -> ERR <text>

The quantities are those of the Modbus register map (REGISTERS.md). A timeout or a garbled
answer is retried after reopening the port; after ``retries`` the driver raises
``ExtruderLinkError`` like the Modbus driver.
"""

from __future__ import annotations

import time
from typing import Any

from mesp_cell.drivers.extruder_base import ExtruderLinkError, ExtruderReading


class SerialExtruder:
    """The extruder controller on serial port ``url`` (any pyserial URL or device path)."""

    def __init__(self, url: str, baudrate: int = 115200, timeout: float = 0.2,
                 retries: int = 3, retry_delay: float = 0.05) -> None:
        self.url, self.baudrate, self.timeout = url, baudrate, timeout
        self.retries, self.retry_delay = retries, retry_delay
        self.rate_set = 0.0
        self._hb = 0
        self._port: Any = None

    def _open(self) -> None:
        import serial

        if self._port is None:
            self._port = serial.serial_for_url(self.url, baudrate=self.baudrate,
                                               timeout=self.timeout)

    def _drop(self) -> None:
        if self._port is not None:
            try:
                self._port.close()
            except Exception:  # a vanished device may refuse to close; it is gone either way
                pass
            self._port = None

    def _ask(self, line: str, expect: str = "OK") -> str:
        import serial

        delay, last = self.retry_delay, ""
        for attempt in range(self.retries + 1):
            try:
                self._open()
                self._port.reset_input_buffer()
                self._port.write((line + "\n").encode())
                answer = self._port.readline().decode(errors="replace").strip()
                if answer.startswith(expect):
                    return answer
                last = f"answered '{answer}'" if answer else "no answer"
                if answer.startswith("ERR"):
                    raise ExtruderLinkError(f"extruder refused '{line}': {answer[4:]}")
            except (serial.SerialException, OSError) as exc:
                last = str(exc)
                self._drop()
            if attempt < self.retries:
                time.sleep(delay)
                delay *= 2
        raise ExtruderLinkError(f"extruder on {self.url} did not answer '{line}' after "
                                f"{self.retries + 1} attempts ({last})")

    def connect(self) -> None:
        self._ask("STAT?", "STAT")

    def close(self) -> None:
        self._drop()

    def start(self, rate: float) -> None:
        self.heartbeat()
        self.rate_set = float(rate)
        self._ask(f"RUN {self.rate_set:.6g}")

    def set_rate(self, rate: float) -> None:
        self.rate_set = float(rate)
        self._ask(f"RATE {self.rate_set:.6g}")

    def stop(self) -> None:
        self._ask("STOP")

    def estop(self) -> None:
        self._ask("ESTOP")

    def reset(self) -> None:
        self._ask("RESET")

    def heartbeat(self) -> None:
        self._hb = (self._hb + 1) & 0xFFFF
        self._ask(f"HB {self._hb}")

    def read(self) -> ExtruderReading:
        parts = self._ask("STAT?", "STAT").split()
        try:
            running, rate_set, rate, volume, fault, hb = parts[1:7]
            return ExtruderReading(float(rate_set), float(rate), float(volume),
                                   running == "1", int(fault), int(hb))
        except ValueError as exc:
            raise ExtruderLinkError(f"extruder on {self.url} sent a bad status "
                                    f"'{' '.join(parts)}'") from exc
