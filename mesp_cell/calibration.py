"""Calibration of the extrusion rate C (paper sections 3.2, 5.2): weigh what the extruder delivers.

The extruder runs at the set-point the cell prints with, into a tared cup, for several run
times; each run's net mass over the density is the volume it really delivered. A straight line
``mass = rho (C t + V0)`` fitted by least squares over the runs gives C (its slope) with its
standard uncertainty, and V0, the start-up transient (what the compressed silicone lags behind,
or oozes, at each start and stop), which a single run's mass / time would mistake for rate.

Masses are checked before they are used: each against the mass the current profile expects for
its run (a band around it: a wrong cup, a missed tare, a typo in grams vs mg), and each run
against the line of the others (a spill, a cup knocked, a run cut short).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import stats

from core.errors import InputError
from mesp_cell.drivers.extruder_base import ExtruderDriver

MIN_RUNS = 3  # a slope and its uncertainty need one degree of freedom


@dataclass(frozen=True)
class RateFit:
    """Result of an extrusion-rate calibration.

    Attributes:
        setpoint: float, mm^3/s, the rate the extruder was commanded (the profile's set-point).
        seconds: (n,) float64, s, run time of each run.
        mass: (n,) float64, g, net weighed output of each run.
        density: float, g/cm^3.
        C: float, mm^3/s, fitted true rate at ``setpoint``.
        u_C: float, mm^3/s, standard uncertainty of C (from the scatter of the runs).
        v0: float, mm^3, intercept: volume at t = 0 (start-up transient, < 0 = lag).
        residual_g: (n,) float64, g, measured - fitted mass.
    """

    setpoint: float
    seconds: NDArray[np.float64]
    mass: NDArray[np.float64]
    density: float
    C: float
    u_C: float
    v0: float
    residual_g: NDArray[np.float64]

    @property
    def relative_uncertainty(self) -> float:
        """u(C) / C."""
        return self.u_C / self.C

    def expanded(self, level: float = 0.95) -> float:
        """mm^3/s, half-width of the ``level`` confidence interval of C (Student t)."""
        dof = max(self.seconds.size - 2, 1)
        return float(stats.t.ppf(0.5 + level / 2, dof) * self.u_C)

    def mass_at(self, t: ArrayLike) -> NDArray[np.float64]:
        """g, the fitted mass after ``t`` s."""
        return (self.C * np.asarray(t, dtype=np.float64) + self.v0) * self.density / 1000.0


def _line(t: NDArray[np.float64], m: NDArray[np.float64]) -> tuple[float, float, float]:
    """(slope, intercept, standard error of the slope) of m over t by least squares."""
    A = np.stack([t, np.ones_like(t)], axis=1)
    (slope, intercept), *_ = np.linalg.lstsq(A, m, rcond=None)
    dof = t.size - 2
    resid = m - (slope * t + intercept)
    sxx = float(np.sum((t - t.mean()) ** 2))
    se = float(np.sqrt(np.sum(resid**2) / dof / sxx)) if dof > 0 and sxx > 0 else float("nan")
    return float(slope), float(intercept), se


def check_runs(seconds: ArrayLike) -> None:
    """Refuse run times that cannot give C and its uncertainty (before anything runs)."""
    t = np.asarray(seconds, dtype=np.float64).ravel()
    if t.size < MIN_RUNS or np.unique(t).size < 2:
        raise InputError(f"{t.size} run(s) of {np.unique(t).size} length(s) give no "
                         "uncertainty of the rate",
                         f"weigh at least {MIN_RUNS} runs of at least 2 lengths, e.g. "
                         "--seconds 30,60,90,120")


def fit_rate(seconds: ArrayLike, mass: ArrayLike, density: float, setpoint: float) -> RateFit:
    """Fit ``mass = rho (C t + V0)`` over the runs (module docstring)."""
    t = np.asarray(seconds, dtype=np.float64).ravel()
    m = np.asarray(mass, dtype=np.float64).ravel()
    if t.shape != m.shape:
        raise InputError(f"{t.size} run times but {m.size} masses", "give one mass per run")
    check_runs(t)
    if not density > 0:
        raise InputError(f"density {density} g/cm^3 is not positive", "give --density")
    if np.any(~np.isfinite(m)) or np.any(m <= 0) or np.any(t <= 0):
        raise InputError("a run has no positive mass or time",
                         "check the extruder and the scale, then redo the run")
    grams_per_mm3 = density / 1000.0
    slope, intercept, se = _line(t, m)
    if slope <= 0:
        raise InputError("the weighed mass does not grow with the run time",
                         "check the scale readings (tare before each run)")
    C = slope / grams_per_mm3
    return RateFit(float(setpoint), t, m, float(density), C, se / grams_per_mm3,
                   intercept / grams_per_mm3, m - (slope * t + intercept))


def check_mass(run: int, seconds: float, mass: float, expected_rate: float, density: float,
               band: float) -> str:
    """'' if ``mass`` (g) is plausible for a run of ``seconds`` at ``expected_rate`` mm^3/s,
    else why not (within ``band``, a fraction, of the expected mass)."""
    expected = expected_rate * seconds * density / 1000.0
    lo, hi = expected * (1 - band), expected * (1 + band)
    if lo <= mass <= hi:
        return ""
    return (f"run {run + 1}: {mass:.4g} g is outside the plausible {lo:.4g}-{hi:.4g} g "
            f"({expected:.4g} g expected from {expected_rate:.4g} mm^3/s for {seconds:g} s, "
            f"+-{band:.0%})")


def check_consistency(seconds: ArrayLike, mass: ArrayLike, tolerance: float) -> str:
    """'' if the runs agree, else which one does not and by how much: the run whose removal
    leaves the straightest line of the others (ties: the furthest from that line) is off
    by more than ``tolerance`` (a fraction of its mass) from it."""
    t = np.asarray(seconds, dtype=np.float64)
    m = np.asarray(mass, dtype=np.float64)
    n = t.size
    if n < MIN_RUNS:
        return ""
    best: tuple[float, float, int, float] | None = None
    for i in range(n):  # a handful of runs: leave-one-out, one line each
        keep = np.arange(n) != i
        if np.unique(t[keep]).size < 2:
            continue
        slope, intercept, _ = _line(t[keep], m[keep])
        ssr = float(np.sum((m[keep] - slope * t[keep] - intercept) ** 2))
        dev = float(m[i] / (slope * t[i] + intercept) - 1.0)
        key = (round(ssr, 12), -abs(dev), i, dev)
        if best is None or key < best:
            best = key
    if best is None or -best[1] <= tolerance:
        return ""
    i, dev = best[2], best[3]
    return (f"run {i + 1} ({t[i]:g} s, {m[i]:.4g} g) disagrees with the other runs "
            f"by {dev:+.1%} (more than {tolerance:.0%})")


def run_extrusion(driver: ExtruderDriver, setpoint: float, seconds: Sequence[float],
                  before_run: Callable[[int, float], None],
                  during_run: Callable[[int, float, float], None],
                  weigh: Callable[[int, float], float], settle_s: float = 2.0,
                  time_scale: float = 1.0) -> list[float]:
    """Run the extruder at ``setpoint`` for each run time; the net mass (g) of each run.

    ``before_run(i, t)`` readies run i (cup, tare, countdown), ``during_run(i, elapsed, t)``
    shows progress, ``weigh(i, t)`` returns the run's net mass (typed or read, checked).
    The flow settles ``settle_s`` after each stop so the cup holds the whole run. Times are on
    the extruder's clock, ``time_scale`` times the wall clock (1 but for an emulated extruder).
    """
    if not setpoint > 0:
        raise InputError(f"set-point {setpoint} mm^3/s", "give a positive --setpoint")
    masses: list[float] = []
    driver.connect()
    try:
        for i, t in enumerate(seconds):
            before_run(i, float(t))
            driver.start(float(setpoint))
            t0 = time.monotonic()
            while (elapsed := (time.monotonic() - t0) * time_scale) < t:
                driver.heartbeat()
                during_run(i, elapsed, float(t))
                time.sleep(min(0.05, (t - elapsed) / time_scale))
            driver.stop()
            end = time.monotonic() + settle_s / time_scale
            while time.monotonic() < end:
                driver.heartbeat()
                time.sleep(0.05)
            reading = driver.read()
            if reading.fault:
                raise InputError(f"the extruder faulted during run {i + 1} "
                                 f"(fault bits {reading.fault:#x})", "clear it and redo the run")
            masses.append(float(weigh(i, float(t))))
    finally:
        try:
            driver.stop()
        finally:
            driver.close()
    return masses
