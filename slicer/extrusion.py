"""Extrusion model: constant volumetric rate C and the speed-morphology relation (paper eq. 4).

The extruder delivers a constant volume rate C (mm^3/s). The filament cross-section depends
on the nozzle speed v (paper section 3.1): ``filament_size(v) -> (w_f, h_f)``. With the overlap
ratio beta (H = beta * h_f, paper section 3.2) the speed for a layer height H is
``v = f(H / beta)``, where f inverts h_f(v), and the toolpath width that conserves volume is
``W = C / (H v)`` (eq. 4). f is a monotone log-log PCHIP interpolant of the profile's table,
clamped to the table's range (outside it the speed saturates; W still follows eq. 4 so the
deposited volume stays correct, only the filament shape is extrapolated).

The profile is the one owner of C, of the set-point that makes the extruder deliver C and of
the morphology table: a job records the exact profile text it was sliced with
(``PROFILE_FILE`` in its directory, identified by its sha256), and the planner and the cell read
them from there.
"""

from __future__ import annotations

import functools
import hashlib
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import PchipInterpolator

from core.artifacts import atomic_write_bytes
from core.errors import InputError

PROFILE_FILE = "profile.toml"  # the job directory's verbatim copy of its profile
ACTIVE = "active"  # the job's profile name for "the cell's active profile"


@dataclass(frozen=True, eq=False)
class ExtrusionProfile:
    """A material's extrusion calibration.

    Attributes:
        name: profile name.
        rate_mm3_s: float, mm^3/s, constant extrusion rate C (the true, weighed rate).
        setpoint_mm3_s: float, mm^3/s, the set-point the extruder is commanded to deliver C.
        beta: float, overlap ratio H / h_f, in (0, 1].
        speed: (k,) float64, mm/s, strictly increasing table speeds.
        filament_width: (k,) float64, mm, w_f at each speed, non-increasing.
        filament_height: (k,) float64, mm, h_f at each speed, strictly decreasing.
        provenance: free text: where C, beta and the table come from.
        calibrated: bool, C was measured at the cell (``mesp calibrate extrusion``).
        text: the profile's TOML text as read ("" for a profile built in code).
    """

    name: str
    rate_mm3_s: float
    setpoint_mm3_s: float
    beta: float
    speed: NDArray[np.float64]
    filament_width: NDArray[np.float64]
    filament_height: NDArray[np.float64]
    provenance: str = ""
    calibrated: bool = False
    text: str = field(default="", repr=False)
    _f: PchipInterpolator = field(init=False, repr=False)
    _w: PchipInterpolator = field(init=False, repr=False)
    _h: PchipInterpolator = field(init=False, repr=False)

    def __post_init__(self) -> None:
        fix = "fix the profile's [morphology] table or rate_mm3_s / beta"
        for attr in ("speed", "filament_width", "filament_height"):
            arr = np.array(getattr(self, attr), dtype=np.float64).ravel()
            arr.setflags(write=False)
            object.__setattr__(self, attr, arr)
        v, w, h = self.speed, self.filament_width, self.filament_height
        if not (np.isfinite(self.rate_mm3_s) and self.rate_mm3_s > 0):
            raise InputError(f"profile '{self.name}': rate_mm3_s = {self.rate_mm3_s}", fix)
        if not (np.isfinite(self.setpoint_mm3_s) and self.setpoint_mm3_s > 0):
            raise InputError(f"profile '{self.name}': setpoint_mm3_s = {self.setpoint_mm3_s}",
                             "fix the profile's setpoint_mm3_s (the rate the extruder is "
                             "commanded)")
        if not (np.isfinite(self.beta) and 0 < self.beta <= 1):
            raise InputError(f"profile '{self.name}': beta = {self.beta}, need 0 < beta <= 1", fix)
        if not (len(v) == len(w) == len(h)) or len(v) < 2:
            raise InputError(
                f"profile '{self.name}': table columns need equal length >= 2 "
                f"(got {len(v)}, {len(w)}, {len(h)})",
                fix,
            )
        if not (np.all(np.isfinite(np.r_[v, w, h])) and np.all(np.r_[v, w, h] > 0)):
            raise InputError(f"profile '{self.name}': table values must be positive", fix)
        if np.any(np.diff(v) <= 0):
            raise InputError(f"profile '{self.name}': speeds must strictly increase", fix)
        if np.any(np.diff(h) >= 0):
            raise InputError(
                f"profile '{self.name}': filament height must strictly decrease with speed",
                fix,
            )
        if np.any(np.diff(w) > 0):
            raise InputError(
                f"profile '{self.name}': filament width must not increase with speed", fix
            )
        lv, lw, lh = np.log(v), np.log(w), np.log(h)
        # f: log h_f -> log v. PCHIP keeps the monotone data monotone (no overshoot).
        object.__setattr__(self, "_f", PchipInterpolator(lh[::-1], lv[::-1], extrapolate=False))
        object.__setattr__(self, "_w", PchipInterpolator(lv, lw, extrapolate=False))
        object.__setattr__(self, "_h", PchipInterpolator(lv, lh, extrapolate=False))

    @property
    def sha256(self) -> str:
        """Hex sha256 of the profile's text: what identifies a calibration."""
        return hashlib.sha256(self.text.encode()).hexdigest()

    def save_to_job(self, job_dir: Path) -> Path:
        """Write the profile's verbatim text into ``job_dir/PROFILE_FILE``."""
        if not self.text:
            raise InputError(f"profile '{self.name}' has no file text to record",
                             "load it with load_profile")
        path = Path(job_dir) / PROFILE_FILE
        atomic_write_bytes(path, self.text.encode())
        return path

    @property
    def height_range(self) -> tuple[float, float]:
        """(min, max) filament height h_f of the table, mm."""
        return float(self.filament_height[-1]), float(self.filament_height[0])

    @property
    def layer_height_range(self) -> tuple[float, float]:
        """(min, max) layer height H = beta h_f the table covers, mm."""
        lo, hi = self.height_range
        return self.beta * lo, self.beta * hi

    def speed_for_height(self, h_f: ArrayLike) -> NDArray[np.float64]:
        """The fitted f: nozzle speed (mm/s) for filament height ``h_f`` (mm), any shape.

        Heights outside the table are clamped to it (the speed saturates at the table ends).
        """
        lo, hi = self.height_range
        hh = np.clip(np.asarray(h_f, dtype=np.float64), lo, hi)
        return np.exp(self._f(np.log(hh)))

    def filament_size(self, v: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(w_f, h_f), mm, of the filament printed at speed ``v`` (mm/s), clamped to the table."""
        vv = np.clip(np.asarray(v, dtype=np.float64), self.speed[0], self.speed[-1])
        lv = np.log(vv)
        return np.exp(self._w(lv)), np.exp(self._h(lv))

    def speed_at(self, H: ArrayLike) -> NDArray[np.float64]:
        """Nozzle speed v = f(H / beta), mm/s, for layer height ``H`` (mm)."""
        return self.speed_for_height(np.asarray(H, dtype=np.float64) / self.beta)

    def width(self, H: ArrayLike) -> NDArray[np.float64]:
        """Toolpath width W = C / (H f(H / beta)), mm (paper eq. 4), for layer height H (mm)."""
        hh = np.asarray(H, dtype=np.float64)
        if np.any(hh <= 0):
            raise InputError("layer height must be positive to compute a width", "re-slice")
        return self.rate_mm3_s / (hh * self.speed_at(hh))

    def in_range(self, H: ArrayLike) -> NDArray[np.bool_]:
        """True where layer height ``H`` (mm) lies inside the table (no clamping)."""
        lo, hi = self.layer_height_range
        hh = np.asarray(H, dtype=np.float64)
        return (hh >= lo) & (hh <= hi)

    def area_consistency(self) -> float:
        """Max |A v / C - 1| over the table with A = pi/4 w_f h_f (0 = volume-consistent)."""
        area = 0.25 * np.pi * self.filament_width * self.filament_height
        return float(np.max(np.abs(area * self.speed / self.rate_mm3_s - 1.0)))


def load_profile(name_or_path: str | Path) -> ExtrusionProfile:
    """Load a bundled profile by name (``ecoflex-0030``) or a profile TOML by path.

    ``ACTIVE`` is resolved by the cell runtime to the cell's active profile; the library alone
    has no cell, and takes the factory profile (``slicer.profiles.FACTORY``) for it.

    Raises:
        InputError: unknown name, unreadable file, missing keys or an invalid table.
    """
    from slicer.profiles import FACTORY

    text_name = FACTORY if str(name_or_path) == ACTIVE else str(name_or_path)
    path = Path(text_name)
    if path.suffix == ".toml" or path.is_file():
        if not path.is_file():
            raise InputError(f"extrusion profile {path} does not exist", "check the path")
        text = path.read_text()
        where = str(path)
    else:
        from slicer.profiles import bundled_names

        resource = resources.files("slicer.profiles").joinpath(f"{text_name}.toml")
        if not resource.is_file():
            raise InputError(
                f"unknown extrusion profile '{text_name}'",
                f"use one of {', '.join(bundled_names())} or a path to a profile .toml",
            )
        text = resource.read_text()
        where = text_name
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"extrusion profile {where} is not valid TOML ({exc})", "fix it") from exc
    return profile_from_dict(data, where, text)


@functools.cache
def factory_rate() -> float:
    """C of the factory profile, mm^3/s: the default of models built without a profile."""
    return load_profile(ACTIVE).rate_mm3_s


def load_job_profile(job_dir: Path) -> ExtrusionProfile:
    """The profile a job was sliced with (``job_dir/PROFILE_FILE``).

    Raises:
        InputError: the job has no recorded profile (sliced by an older version) or it is bad.
    """
    path = Path(job_dir) / PROFILE_FILE
    if not path.is_file():
        raise InputError(f"job {Path(job_dir).name} records no extrusion profile ({path})",
                         "re-slice the job (re-submit it)")
    return load_profile(path)


def profile_from_dict(data: dict, where: str = "profile", text: str = "") -> ExtrusionProfile:
    """Build a profile from parsed TOML (keys as in ``slicer/profiles/ecoflex-0030.toml``)."""
    fix = "see slicer/profiles/ecoflex-0030.toml for the format"
    try:
        table = data["morphology"]
        return ExtrusionProfile(
            name=str(data.get("name", where)),
            rate_mm3_s=float(data["rate_mm3_s"]),
            setpoint_mm3_s=float(data["setpoint_mm3_s"]),
            beta=float(data["beta"]),
            speed=np.asarray(table["speed_mm_s"], dtype=np.float64),
            filament_width=np.asarray(table["filament_width_mm"], dtype=np.float64),
            filament_height=np.asarray(table["filament_height_mm"], dtype=np.float64),
            provenance=str(data.get("provenance", "")),
            calibrated=bool(data.get("calibrated", False)),
            text=text,
        )
    except KeyError as exc:
        raise InputError(f"extrusion profile {where} lacks key {exc}", fix) from exc
    except (TypeError, ValueError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"extrusion profile {where} has a bad value ({exc})", fix) from exc
