"""Calibration of the extrusion rate C and of the filament morphology f (paper sections 3, 5.2).

Extrusion: the extruder runs at each set-point for a set time into a cup; the cup's mass (typed
in, or read from a serial scale) over the material density (from the profile) is the true
volume. The controller's totaliser gives the nominal volume of the same run, so the ratio is
independent of the flow's ramp-up; the true rate ``gain * set-point`` is fitted against the
set-point by least squares: ``rate = slope * setpoint + intercept``. C is the fitted rate at the
operating set-point.

Morphology: a CSV of measured filament cross-sections (speed, width, height) is fitted with
power laws ``h_f = a_h v^b_h`` and ``w_f = a_w v^b_w`` (linear least squares in log-log), the
form of the volume-conserving model (A = C / v) that the bundled profile uses; the fit is
sampled at log-spaced speeds over the measured range into the profile's morphology table,
which is strictly monotone when ``b_h < 0``.

Both write the profile format the slicer reads (``slicer/profiles/ecoflex-0030.toml``).
"""

from __future__ import annotations

import csv
import re
import time
import tomllib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from mesp_cell.drivers.extruder_base import ExtruderDriver
from slicer.errors import InputError
from slicer.progress import NullProgress, Progress

# Ecoflex 00-30 specific gravity 1.07 (Smooth-On technical bulletin): used when a profile
# carries no density of its own.
DEFAULT_DENSITY_G_CM3 = {"ecoflex-0030": 1.07}


@dataclass(frozen=True)
class RateFit:
    """Result of an extrusion-rate calibration.

    Attributes:
        setpoints: (n,) float64, mm^3/s, commanded rates.
        seconds: float, s, run time per set-point.
        nominal_volume: (n,) float64, mm^3, controller totaliser over each run.
        mass: (n,) float64, g, weighed output of each run.
        density: float, g/cm^3.
        true_rate: (n,) float64, mm^3/s, set-point * true/nominal volume.
        slope: float, true rate per set-point (1 = ideal). intercept: float, mm^3/s.
        r2: float, coefficient of determination of the line.
        operating_setpoint: float, mm^3/s, the set-point the cell prints at.
        C: float, mm^3/s, fitted true rate at the operating set-point.
    """

    setpoints: np.ndarray
    seconds: float
    nominal_volume: np.ndarray
    mass: np.ndarray
    density: float
    true_rate: np.ndarray
    slope: float
    intercept: float
    r2: float
    operating_setpoint: float
    C: float

    def setpoint_for(self, rate: float) -> float:
        """Set-point (mm^3/s) that delivers ``rate`` mm^3/s by the fitted line."""
        return (rate - self.intercept) / self.slope


def fit_rate(setpoints: ArrayLike, nominal_volume: ArrayLike, mass: ArrayLike,
             seconds: float, density: float,
             operating_setpoint: float = 6.57) -> RateFit:
    """Fit true rate vs set-point from weighed runs (see the module docstring)."""
    s = np.asarray(setpoints, dtype=np.float64)
    vn = np.asarray(nominal_volume, dtype=np.float64)
    m = np.asarray(mass, dtype=np.float64)
    if not (s.shape == vn.shape == m.shape) or s.size < 1:
        raise InputError("set-points, volumes and masses differ in number", "redo the runs")
    if density <= 0:
        raise InputError(f"density {density} g/cm^3 is not positive", "give --density")
    if np.any(m <= 0) or np.any(vn <= 0):
        raise InputError("a run produced no mass or no totalised volume",
                         "check the extruder and the scale, then redo the run")
    true_volume = m / density * 1000.0  # g / (g/cm^3) = cm^3 -> mm^3
    rate = s * true_volume / vn
    if s.size >= 2 and np.ptp(s) > 0:
        A = np.stack([s, np.ones_like(s)], axis=1)
        (slope, intercept), *_ = np.linalg.lstsq(A, rate, rcond=None)
        resid = rate - (slope * s + intercept)
        tot = float(np.sum((rate - rate.mean()) ** 2))
        r2 = 1.0 - float(np.sum(resid**2)) / tot if tot > 0 else 1.0
    else:  # one set-point: a line through the origin
        slope, intercept, r2 = float(np.sum(rate * s) / np.sum(s * s)), 0.0, 1.0
    if slope <= 0:
        raise InputError("the measured rate does not grow with the set-point",
                         "check the scale readings")
    C = float(slope * operating_setpoint + intercept)
    return RateFit(s, float(seconds), vn, m, float(density), rate, float(slope),
                   float(intercept), float(r2), float(operating_setpoint), C)


def run_extrusion(driver: ExtruderDriver, setpoints: Sequence[float], seconds: float,
                  weigh: Callable[[int, float], float], density: float,
                  operating_setpoint: float = 6.57, settle_s: float = 1.0,
                  progress: Progress | None = None) -> RateFit:
    """Run the extruder at each set-point for ``seconds``, weigh each run, fit.

    ``weigh(i, setpoint)`` returns the mass in g of run ``i`` (a prompt, or a serial scale).
    The extruder stops after each run and the flow settles for ``settle_s`` so the
    totaliser and the cup both hold the whole run.
    """
    progress = progress or NullProgress()
    if seconds <= 0 or not setpoints:
        raise InputError("need at least one set-point and a positive run time",
                         "give --setpoints and --seconds")
    volumes, masses = [], []
    driver.connect()
    try:
        for i, sp in enumerate(setpoints):  # one physical run per set-point
            progress.start(f"run {i + 1}/{len(setpoints)} at {sp:g} mm^3/s")
            t0 = time.monotonic()
            v0 = driver.read().volume
            driver.start(float(sp))
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                driver.heartbeat()
                progress.update(1.0 - (end - time.monotonic()) / seconds)
                time.sleep(0.05)
            driver.stop()
            settle_end = time.monotonic() + settle_s
            while time.monotonic() < settle_end:
                driver.heartbeat()
                time.sleep(0.05)
            reading = driver.read()
            if reading.fault:
                raise InputError(f"the extruder faulted during run {i + 1} "
                                 f"(fault bits {reading.fault:#x})", "clear it and redo the run")
            volumes.append(reading.volume - v0)
            progress.end(f"run {i + 1}/{len(setpoints)} at {sp:g} mm^3/s", time.monotonic() - t0)
            masses.append(float(weigh(i, float(sp))))
    finally:
        try:
            driver.stop()
        finally:
            driver.close()
    return fit_rate(setpoints, volumes, masses, seconds, density, operating_setpoint)


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


@dataclass(frozen=True)
class MorphologyFit:
    """Result of a morphology calibration.

    Attributes:
        speed: (k,) float64, mm/s, table speeds (log-spaced over the measured range).
        width: (k,) float64, mm, fitted filament width w_f.
        height: (k,) float64, mm, fitted filament height h_f (strictly decreasing).
        a_w, b_w, a_h, b_h: power-law coefficients (mm, with v in mm/s).
        r2_w, r2_h: coefficients of determination in log space.
        samples: number of measured rows.
    """

    speed: np.ndarray
    width: np.ndarray
    height: np.ndarray
    a_w: float
    b_w: float
    a_h: float
    b_h: float
    r2_w: float
    r2_h: float
    samples: int


def read_morphology_csv(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(speed mm/s, width mm, height mm) columns of a CSV with a header naming them.

    Accepted headers: ``speed_mm_s``/``speed``, ``width_mm``/``width``, ``height_mm``/``height``.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"table {path} does not exist", "check the path")
    with open(path, newline="") as f:
        rows = list(csv.DictReader(row for row in f if row.strip() and not row.startswith("#")))
    if not rows:
        raise InputError(f"{path} has no data rows", "add a header and one row per filament")

    def column(*names: str) -> np.ndarray:
        for name in names:
            if name in rows[0]:
                try:
                    return np.array([float(r[name]) for r in rows], dtype=np.float64)
                except (TypeError, ValueError) as exc:
                    raise InputError(f"{path}: column '{name}' holds a non-number ({exc})",
                                     "fix the table") from exc
        raise InputError(f"{path} has no column {names[0]}",
                         "the header needs speed_mm_s, width_mm, height_mm")

    v, w, h = column("speed_mm_s", "speed"), column("width_mm", "width"), column(
        "height_mm", "height")
    if np.any(~np.isfinite(np.r_[v, w, h])) or np.any(np.r_[v, w, h] <= 0):
        raise InputError(f"{path}: every speed, width and height must be positive",
                         "fix the table")
    return v, w, h


def _loglog(v: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    lv, ly = np.log(v), np.log(y)
    A = np.stack([np.ones_like(lv), lv], axis=1)
    (c, b), *_ = np.linalg.lstsq(A, ly, rcond=None)
    resid = ly - (c + b * lv)
    tot = float(np.sum((ly - ly.mean()) ** 2))
    r2 = 1.0 - float(np.sum(resid**2)) / tot if tot > 0 else 1.0
    return float(np.exp(c)), float(b), r2


def fit_morphology(speed: np.ndarray, width: np.ndarray, height: np.ndarray,
                   points: int = 13) -> MorphologyFit:
    """Fit the power laws and sample the profile table (see the module docstring)."""
    v = np.asarray(speed, dtype=np.float64)
    if np.unique(v).size < 2:
        raise InputError("the table needs filaments printed at two speeds at least",
                         "print and measure at more speeds")
    a_w, b_w, r2_w = _loglog(v, np.asarray(width, dtype=np.float64))
    a_h, b_h, r2_h = _loglog(v, np.asarray(height, dtype=np.float64))
    if b_h >= 0:
        raise InputError(f"the measured filament height does not fall with speed "
                         f"(exponent {b_h:.3f})", "check the measurements (paper Fig. 2d)")
    if b_w > 0:
        raise InputError(f"the measured filament width grows with speed (exponent {b_w:.3f})",
                         "check the measurements (paper Fig. 2d)")
    table_v = np.geomspace(v.min(), v.max(), points)
    return MorphologyFit(table_v, a_w * table_v**b_w, a_h * table_v**b_h, a_w, b_w, a_h, b_h,
                         r2_w, r2_h, int(v.size))


def base_profile(name_or_path: str | Path) -> dict[str, Any]:
    """The parsed TOML of a bundled profile name or a profile path (to start from)."""
    path = Path(str(name_or_path))
    if path.suffix == ".toml" or path.is_file():
        if not path.is_file():
            raise InputError(f"profile {path} does not exist", "check the path")
        text = path.read_text()
    else:
        res = resources.files("slicer.profiles").joinpath(f"{name_or_path}.toml")
        if not res.is_file():
            raise InputError(f"unknown profile '{name_or_path}'", "give a profile .toml path")
        text = res.read_text()
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"profile {name_or_path} is not valid TOML ({exc})", "fix it") from exc


def profile_density(data: dict[str, Any], override: float | None = None) -> float:
    """Density g/cm^3: ``override``, the profile's ``density_g_cm3``, or the known material."""
    if override is not None:
        return float(override)
    if "density_g_cm3" in data:
        return float(data["density_g_cm3"])
    name = str(data.get("name", ""))
    if name in DEFAULT_DENSITY_G_CM3:
        return DEFAULT_DENSITY_G_CM3[name]
    raise InputError(f"profile '{name}' has no density_g_cm3", "give --density G_PER_CM3")


def write_profile(data: dict[str, Any], out: Path, rate: RateFit | None = None,
                  morphology: MorphologyFit | None = None) -> Path:
    """Write ``data`` updated with the calibration results to ``out`` (profile TOML).

    The result is validated by ``slicer.extrusion.profile_from_dict`` before it is written.
    """
    import tomli_w

    from slicer.artifacts import atomic_write_bytes
    from slicer.extrusion import profile_from_dict

    data = {k: v for k, v in data.items()}
    calib = dict(data.get("calibration", {}))
    stamp = time.strftime("%Y-%m-%dT%H:%M:%S")
    notes = [str(data.get("provenance", ""))] if data.get("provenance") else []
    if rate is not None:
        data["rate_mm3_s"] = round(rate.C, 4)
        data["density_g_cm3"] = rate.density
        calib["extrusion"] = {
            "date": stamp, "seconds": rate.seconds, "density_g_cm3": rate.density,
            "setpoint_mm3_s": rate.setpoints.round(4).tolist(),
            "nominal_volume_mm3": rate.nominal_volume.round(3).tolist(),
            "mass_g": rate.mass.round(4).tolist(),
            "true_rate_mm3_s": rate.true_rate.round(4).tolist(),
            "slope": round(rate.slope, 6), "intercept_mm3_s": round(rate.intercept, 6),
            "r2": round(rate.r2, 6), "operating_setpoint_mm3_s": rate.operating_setpoint,
        }
        notes.append(f"C = {rate.C:.3f} mm^3/s measured {stamp} (mesp calibrate extrusion)")
    if morphology is not None:
        m = morphology
        data["morphology"] = {
            "speed_mm_s": m.speed.round(4).tolist(),
            "filament_width_mm": m.width.round(4).tolist(),
            "filament_height_mm": m.height.round(4).tolist(),
        }
        data["calibrated"] = True
        calib["morphology"] = {
            "date": stamp, "samples": m.samples, "width_mm": [m.a_w, m.b_w],
            "height_mm": [m.a_h, m.b_h], "r2_width": round(m.r2_w, 6),
            "r2_height": round(m.r2_h, 6),
            "model": "w_f = a v^b, h_f = a v^b (v in mm/s, lengths in mm)",
        }
        notes.append(f"morphology fitted from {m.samples} measured filaments {stamp} "
                     "(mesp calibrate morphology)")
    data["calibration"] = calib
    data["provenance"] = "; ".join(notes)
    profile_from_dict(data, str(out))  # refuse to write a profile the slicer would refuse
    atomic_write_bytes(Path(out), tomli_w.dumps(data).encode())
    return Path(out)
