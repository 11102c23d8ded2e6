"""The physics of the emulated extruder: first-order flow, totaliser, watchdog and faults.

Shared by the Modbus emulator and the serial emulator so both speak for the same machine. The
``gain`` is the hidden truth that calibration must recover: the controller measures its rate from
the screw speed (``rate``, ``volume``: nominal), but the screw really delivers ``gain`` times that
(``true_volume``), and nothing on the link reports ``gain``; only weighing the output does.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

from mesp_cell.drivers.sim_clock import SimClock, clock_for
from mesp_cell.messages import FAULT_ESTOP, FAULT_STALL, FAULT_WATCHDOG


@dataclass(frozen=True)
class PlantParams:
    """Parameters of the emulated extruder.

    Attributes:
        tau_s: s, time constant of the first-order flow response.
        gain: true delivered volume / nominal volume (hidden from the host).
        max_rate: mm^3/s, set-points are clamped to [0, max_rate].
        watchdog_s: s, host heartbeat timeout while running (0 = off), wall-clock.
        time_scale: the flow and the totaliser run this many times faster than the wall clock
            (1 = real time). On the simulated cell they run on the clock the robot twin
            shares (``sim_clock.SimClock``), which also pauses while the twin lags. The
            watchdog supervises the host link, so it stays on the wall clock.
    """

    tau_s: float = 0.2
    gain: float = 1.0
    max_rate: float = 50.0
    watchdog_s: float = 0.5
    time_scale: float = 1.0

    def __post_init__(self) -> None:
        if not (self.tau_s > 0 and self.gain > 0 and self.max_rate > 0 and self.watchdog_s >= 0
                and self.time_scale > 0):
            raise ValueError("tau_s, gain, max_rate, time_scale must be > 0 and watchdog_s >= 0")


class ExtruderPlant:
    """A thread-safe extruder model advanced by ``step(now)`` (``now`` in s, monotonic wall
    clock). The flow advances on simulated time: ``clock.now(now)``, ``time_scale`` times
    the wall clock less the time the twin paused it (default: a private clock, never paused).
    """

    def __init__(self, params: PlantParams, now: float, clock: SimClock | None = None) -> None:
        self.params = params
        self.clock = clock_for(params.time_scale, clock)
        self.watchdog_s = params.watchdog_s
        self.rate_set = 0.0
        self.rate = 0.0
        self.volume = 0.0
        self.true_volume = 0.0
        self.running = False
        self.fault = 0
        self.stalled = False
        self.cycles = 0
        self._host_hb = -1
        self._host_hb_t = now
        self._sim_t = self.clock.now(now)  # s, simulated time the flow has reached
        self._lock = threading.Lock()

    def step(self, now: float) -> None:
        """Advance the flow and the totaliser to ``now`` (exact for a piecewise constant input)."""
        with self._lock:
            # Simulated seconds since the last step. The twin may pause the clock after this
            # process read it, so simulated time can seem to step back: hold until it passes.
            sim_now = self.clock.now(now)
            dt = max(0.0, sim_now - self._sim_t)
            self._sim_t = max(self._sim_t, sim_now)
            self.cycles = (self.cycles + 1) & 0xFFFF
            if self.running and self.watchdog_s > 0 and now - self._host_hb_t > self.watchdog_s:
                self.running = False
                self.fault |= FAULT_WATCHDOG
            if self.stalled and self.running:
                self.fault |= FAULT_STALL
            on = self.running and not self.stalled and self.fault == 0
            target = self.rate_set if on else 0.0
            decay = math.exp(-dt / self.params.tau_s)
            # Integral of r(t) = target + (r0 - target) e^{-t/tau} over [0, dt].
            dv = target * dt + (self.rate - target) * self.params.tau_s * (1 - decay)
            self.volume += dv
            self.true_volume += self.params.gain * dv
            self.rate = target + (self.rate - target) * decay

    def command(self, word: int, now: float) -> None:
        """Apply a command word (registers.CMD_* bits)."""
        from mesp_cell.drivers import registers as R

        self.step(now)
        with self._lock:
            if word & R.CMD_RESET:
                self.fault = 0
            if word & R.CMD_ESTOP:
                self.fault |= FAULT_ESTOP
                self.running = False
                return
            run = bool(word & R.CMD_RUN)
            if run and not self.running:
                self._host_hb_t = now  # a fresh start gets a full watchdog period
            self.running = run and self.fault == 0

    def set_rate(self, rate: float, now: float) -> None:
        """Set the rate set-point, mm^3/s (clamped to [0, max_rate])."""
        self.step(now)
        with self._lock:
            self.rate_set = min(max(float(rate), 0.0), self.params.max_rate)

    def host_heartbeat(self, value: int, now: float) -> None:
        """The host wrote its heartbeat register; a changed value feeds the watchdog."""
        with self._lock:
            if value != self._host_hb:
                self._host_hb = value
                self._host_hb_t = now

    def set_stall(self, stalled: bool, now: float) -> None:
        """Inject (or clear) a motor stall."""
        self.step(now)
        with self._lock:
            self.stalled = stalled

    def status_word(self) -> int:
        """The STATUS register."""
        from mesp_cell.drivers import registers as R

        at_set = self.running and abs(self.rate - self.rate_set) <= 0.05 * max(
            self.rate_set, 1e-9
        )
        return (
            (R.ST_RUNNING if self.running else 0)
            | (R.ST_AT_SET if at_set else 0)
            | (R.ST_FAULT if self.fault else 0)
            | (R.ST_READY if not self.fault else 0)
        )
