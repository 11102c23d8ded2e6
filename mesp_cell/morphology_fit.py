"""Calibration of the filament morphology f (paper section 3.1, Fig. 3's table).

A CSV of measured filament cross-sections (speed, width, height), printed at the profile's C at
several speeds, is fitted with power laws ``h_f = a_h v^b_h`` and ``w_f = a_w v^b_w`` (linear
least squares in log-log), the form of the volume-conserving model (A = C / v) that the bundled
profile uses; the fit is sampled at log-spaced speeds over the measured range into the profile's
morphology table, which is strictly monotone when ``b_h < 0``.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.errors import InputError


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


