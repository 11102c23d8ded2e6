"""The physics of the emulated extruder: first-order flow, totaliser, watchdog and faults.

Shared by the Modbus emulator and the serial emulator so both speak for the same machine. The
``gain`` is the hidden truth that calibration must recover: the controller measures its rate from
the screw speed (``rate``, ``volume``: nominal), but the screw really delivers ``gain`` times that
(``true_volume``), and nothing on the link reports ``gain``; only weighing the output does.
The true rate at a set-point s is ``gain * s`` once the flow has settled.

Start-up transient: the silicone in the barrel is compressed before it flows, so what leaves
the nozzle follows the screw's flow through a second first-order lag ``startup_tau_s``: it lags
behind at every start and keeps oozing after a stop (the volume is the same once settled).
``mesp_cell.drivers.scale_emulator`` adds the noise of the mass readings.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

from core.tolerance import tol
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
        startup_tau_s: s, lag of the delivered flow behind the screw's (compression; 0 = none).
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
    startup_tau_s: float = 0.0

    def __post_init__(self) -> None:
        if not (self.tau_s > 0 and self.gain > 0 and self.max_rate > 0 and self.watchdog_s >= 0
                and self.time_scale > 0 and self.startup_tau_s >= 0):
            raise ValueError("tau_s, gain, max_rate, time_scale must be > 0, watchdog_s and "
                             "startup_tau_s >= 0")


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
        self.out_rate = 0.0  # mm^3/s (nominal units) leaving the nozzle, behind ``rate``
        self.volume = 0.0
        self.true_volume = 0.0
        self.running = False
        self.fault = 0
        self.stalled = False
        self.slip = 1.0  # fraction of the set-point the screw really turns at (injected slip)
        self.cycles = 0
        self._host_hb = -1
        self._host_hb_t = now
        self._sim_t = self.clock.now(now)  # s, simulated time the flow has reached
        self._lock = threading.Lock()

    def step(self, now: float) -> None:
        """Advance the flow and the totaliser to ``now`` (exact for a piecewise constant input)."""
        with self._lock:
            # Simulated seconds since the last step. The twin holds the clock where it is, but
            # may pause it a few us after this process read it (or after its hold lapsed), so
            # simulated time can seem to step back: hold until it passes.
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
            target = self.rate_set * self.slip if on else 0.0
            tau = self.params.tau_s
            decay = math.exp(-dt / tau)
            e1 = self.rate - target
            # Integral of r(t) = target + e1 e^{-t/tau} over [0, dt].
            dv = target * dt + e1 * tau * (1 - decay)
            self.volume += dv
            self.true_volume += self.params.gain * self._delivered(target, e1, dt)
            self.rate = target + e1 * decay

    def _delivered(self, target: float, e1: float, dt: float) -> float:
        """Volume (nominal units) leaving the nozzle over ``dt``: the screw's flow
        ``target + e1 e^{-t/tau}`` through the lag ``startup_tau_s``; advances ``out_rate``."""
        tau, tau2 = self.params.tau_s, self.params.startup_tau_s
        if tau2 <= 0:
            self.out_rate = target + e1 * math.exp(-dt / tau)
            return target * dt + e1 * tau * (1 - math.exp(-dt / tau))
        if abs(tau2 - tau) < 1e-6 * tau:
            tau2 = tau * (1 + 1e-6)  # the closed form below needs distinct time constants
        e2 = self.out_rate - target
        d1, d2 = math.exp(-dt / tau), math.exp(-dt / tau2)
        k = e1 * tau / (tau - tau2)
        # e2(t) = e2_0 e^{-t/tau2} + k (e^{-t/tau} - e^{-t/tau2}) solves tau2 e2' = e1(t) - e2
        self.out_rate = target + e2 * d2 + k * (d1 - d2)
        return target * dt + e2 * tau2 * (1 - d2) + k * (tau * (1 - d1) - tau2 * (1 - d2))

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

    def set_slip(self, fraction: float, now: float) -> None:
        """Inject a slipping screw turning at ``fraction`` of its set-point (1 = none): no
        fault, only the measured rate shows it."""
        self.step(now)
        with self._lock:
            self.slip = fraction

    def status_word(self) -> int:
        """The STATUS register."""
        from mesp_cell.drivers import registers as R

        at_set = self.running and abs(self.rate - self.rate_set) <= R.AT_SET_BAND * max(
            self.rate_set, tol.floor
        )
        return (
            (R.ST_RUNNING if self.running else 0)
            | (R.ST_AT_SET if at_set else 0)
            | (R.ST_FAULT if self.fault else 0)
            | (R.ST_READY if not self.fault else 0)
        )
