"""Extruder driver over Modbus TCP (pymodbus 3.x synchronous client).

Every exchange is retried: on a timeout or a dropped connection the driver reconnects and
tries again, ``retries`` times with doubling delays; after that it raises ``ExtruderLinkError``
and the extruder node fails safe (state fault, robot stops). Registers: ``registers.py``.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any, TypeVar

from mesp_cell.drivers import registers as R
from mesp_cell.drivers.extruder_base import ExtruderLinkError, ExtruderReading

T = TypeVar("T")


class ModbusExtruder:
    """The extruder controller at ``host:port`` (unit ``unit``).

    Args:
        timeout: s, per request. retries: reconnect-and-retry attempts after a failure.
        retry_delay: s, first delay between attempts (doubles each time).
        watchdog_ms: ms, controller watchdog written on connect (0 = off).
    """

    def __init__(self, host: str, port: int, unit: int = 1, timeout: float = 0.2,
                 retries: int = 3, retry_delay: float = 0.05, watchdog_ms: int = 500) -> None:
        self.host, self.port, self.unit = host, int(port), unit
        self.timeout, self.retries, self.retry_delay = timeout, retries, retry_delay
        self.watchdog_ms = watchdog_ms
        self.rate_set = 0.0
        self._hb = 0
        self._command = 0
        self._client: Any = None
        self.attempts_failed = 0  # failed exchanges since start (for diagnostics)
        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)

    # -- link ------------------------------------------------------------------------------
    def _open(self) -> None:
        from pymodbus.client import ModbusTcpClient

        if self._client is None:
            self._client = ModbusTcpClient(self.host, port=self.port, timeout=self.timeout,
                                           retries=0, reconnect_delay=0)
        if not self._client.connected and not self._client.connect():
            raise ConnectionError(f"cannot connect to {self.host}:{self.port}")

    def _drop(self) -> None:
        if self._client is not None:
            try:
                self._client.close()
            except Exception:  # closing a broken socket may raise; it is gone either way
                pass
            self._client = None

    def _call(self, what: str, fn: Callable[[Any], T]) -> T:
        from pymodbus.exceptions import ModbusException

        delay, last = self.retry_delay, ""
        for attempt in range(self.retries + 1):
            try:
                self._open()
                result = fn(self._client)
                if hasattr(result, "isError") and result.isError():
                    raise ModbusException(f"controller answered {result}")
                return result
            except (ModbusException, OSError, ConnectionError, AttributeError) as exc:
                self.attempts_failed += 1
                last = str(exc) or type(exc).__name__
                self._drop()
                if attempt < self.retries:
                    time.sleep(delay)
                    delay *= 2
        raise ExtruderLinkError(
            f"extruder at {self.host}:{self.port} did not answer '{what}' after "
            f"{self.retries + 1} attempts ({last})"
        )

    def _write(self, address: int, values: list[int], what: str) -> None:
        self._call(what, lambda c: c.write_registers(address, values, device_id=self.unit))

    def connect(self) -> None:
        """Open the link and set the controller watchdog."""
        self._write(R.WATCHDOG_MS, [self.watchdog_ms & 0xFFFF], "set watchdog")

    def close(self) -> None:
        """Close the link (the controller watchdog stops a running motor)."""
        self._drop()

    # -- commands --------------------------------------------------------------------------
    def set_rate(self, rate: float) -> None:
        """Rate set-point, mm^3/s."""
        self.rate_set = float(rate)
        self._write(R.RATE_SET, R.float_to_regs(self.rate_set), "set rate")

    def start(self, rate: float) -> None:
        """Run at ``rate`` mm^3/s: command, set-point and a fresh heartbeat (so the watchdog
        starts fresh) in one exchange, which a stop also takes (a start two exchanges later
        than a stop cost ink at every path)."""
        self.rate_set = float(rate)
        self._command = R.CMD_RUN
        self._hb = (self._hb + 1) & 0xFFFF
        # COMMAND, RATE_SET (2 registers) and HOST_HEARTBEAT are consecutive registers
        self._write(R.COMMAND, [self._command, *R.float_to_regs(self.rate_set), self._hb],
                    "start")

    def stop(self) -> None:
        """Stop the motor."""
        self._command = 0
        self._write(R.COMMAND, [0], "stop")

    def estop(self) -> None:
        """Emergency stop (latches the e-stop fault until ``reset``)."""
        self._command = R.CMD_ESTOP
        self._write(R.COMMAND, [R.CMD_ESTOP], "e-stop")

    def reset(self) -> None:
        """Clear latched faults (motor stays off)."""
        self._command = 0
        self._write(R.COMMAND, [R.CMD_RESET], "reset")

    def heartbeat(self) -> None:
        """Increment the host heartbeat register (call at >= 10 Hz)."""
        self._hb = (self._hb + 1) & 0xFFFF
        self._write(R.HOST_HEARTBEAT, [self._hb], "heartbeat")

    def read(self) -> ExtruderReading:
        """Read status, faults, rate, totaliser and controller heartbeat in one request."""
        start, count = R.READ_BLOCK
        regs = self._call(
            "read", lambda c: c.read_holding_registers(start, count=count, device_id=self.unit)
        ).registers
        o = -start
        return ExtruderReading(
            rate_set=self.rate_set,
            rate=R.regs_to_float(regs[o + R.RATE : o + R.RATE + 2]),
            volume=R.regs_to_u32(regs[o + R.VOLUME : o + R.VOLUME + 2]) / 100.0,
            running=bool(regs[o + R.STATUS] & R.ST_RUNNING),
            fault=int(regs[o + R.FAULT]),
            ctrl_heartbeat=int(regs[o + R.CTRL_HEARTBEAT]),
        )

    def inject(self, kind: int, seconds: float) -> None:
        """Emulator only: inject a fault (``registers.INJECT_*``) for ``seconds``."""
        self._write(R.INJECT, [kind, round(seconds * 10)], "inject")
