"""A second, pre-opened link to the extruder controller that only stops the screw.

The robot node stops the arm in one servo period when an interlock trips; the extruder node may
be the thing that failed (killed, hung), and the controller's own watchdog stops the screw only
after ``WATCHDOG_MS`` (~0.5 s of ink onto a standing nozzle). So the robot node holds its own
Modbus TCP connection to the controller, opened at start, and writes COMMAND = 0 (stop) on it
the moment the arm stops. The write runs on this class's thread: a frozen controller delays it
by at most ``timeout`` without holding the servo loop. Modbus TCP controllers serve several
masters; this link never starts the screw and never feeds the watchdog.
"""

from __future__ import annotations

import logging
import threading
import time

from mesp_cell.drivers import registers as R

log = logging.getLogger("mesp.screw_stop")


class ScrewStop:
    """Stops the screw of the controller at ``host:port`` on ``trigger``.

    Args:
        timeout: s, per write (a frozen controller costs at most this).
        unit: Modbus unit id.

    Attributes:
        last_t: time.time() of the last confirmed stop write (0 = none).
    """

    def __init__(self, host: str, port: int, timeout: float = 0.05, unit: int = 1) -> None:
        from pymodbus.client import ModbusTcpClient

        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
        self.host, self.port, self.unit = host, int(port), unit
        self._client = ModbusTcpClient(host, port=self.port, timeout=timeout, retries=0,
                                       reconnect_delay=0)
        self._want = threading.Event()
        self._closed = threading.Event()
        self.last_t = 0.0
        self.reason = ""
        self._client.connect()  # pre-opened; a failure here is retried at the first stop
        self._thread = threading.Thread(target=self._run, name="screw-stop", daemon=True)
        self._thread.start()

    def trigger(self, reason: str) -> None:
        """Stop the screw now (thread-safe, returns at once)."""
        self.reason = reason
        self._want.set()

    def _run(self) -> None:
        while not self._closed.is_set():
            if not self._want.wait(1.0):
                continue
            self._want.clear()
            for _ in range(3):
                if self._stop_once():
                    break
                if self._closed.is_set() or self._want.is_set():
                    break

    def _stop_once(self) -> bool:
        try:
            if not self._client.connected and not self._client.connect():
                return False
            result = self._client.write_registers(R.COMMAND, [0], device_id=self.unit)
            if result.isError():
                return False
        except Exception as exc:  # a broken link: reconnect on the next attempt
            log.warning("screw stop on %s:%d failed: %s", self.host, self.port, exc)
            self._client.close()
            return False
        self.last_t = time.time()
        log.warning("screw stopped directly on the controller: %s", self.reason)
        return True

    def close(self) -> None:
        self._closed.set()
        self._want.set()
        self._thread.join(1.0)
        self._client.close()
