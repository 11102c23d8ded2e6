"""The lab's extrusion profiles and each cell's active calibration.

A lab keeps its profiles as files in ``$MESP_HOME/profiles/<name>.toml`` (written by
``mesp calibrate``); the bundled profiles (``slicer/profiles``) are there too, read-only. Each
cell has one active profile: a verbatim copy in ``$MESP_HOME/profiles/active/<cell>.toml``, so
editing or deleting a library file never changes what the cell prints with. Until a lab activates
one, a cell's active profile is the factory profile (``slicer.profiles.FACTORY``).

A job is sliced with its cell's active profile (the job file's ``[extrusion] profile =
"active"``) and records the exact text (``slicer.extrusion.PROFILE_FILE``); the supervisor
refuses to print a job whose profile is not the cell's active one (``stale_reason``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from core.artifacts import atomic_write_bytes
from core.errors import InputError
from mesp_cell.bus.secret import mesp_home
from slicer.extrusion import ACTIVE, ExtrusionProfile, load_profile
from slicer.profiles import FACTORY, bundled_names

NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._\-]*$")


def library_dir() -> Path:
    """Where the lab's profiles are kept."""
    return mesp_home() / "profiles"


def active_file(cell: str) -> Path:
    """The copy of ``cell``'s active profile (may not exist: the factory profile is active)."""
    return library_dir() / "active" / f"{cell}.toml"


def default_cell() -> str:
    """The cell a console command means without ``--on``: the only one running, else 'sim'."""
    run_dir = mesp_home() / "run"
    runs = sorted(run_dir.glob("*.json")) if run_dir.is_dir() else []
    return runs[0].stem if len(runs) == 1 else "sim"


def check_name(name: str) -> str:
    """``name`` if it can name a profile file, else an ``InputError``."""
    if not NAME.match(name):
        raise InputError(f"profile name '{name}' is not a file name",
                         "use letters, digits, '.', '_' and '-'")
    return name


@dataclass(frozen=True)
class Entry:
    """One profile the lab has: name, where it is, bundled or the lab's own."""

    name: str
    path: Path | None  # None: bundled
    bundled: bool

    def load(self) -> ExtrusionProfile:
        """The profile itself."""
        return load_profile(self.path if self.path is not None else self.name)


def entries() -> list[Entry]:
    """Every profile: the lab's first (sorted), then the bundled ones it does not shadow."""
    lab = sorted(library_dir().glob("*.toml")) if library_dir().is_dir() else []
    out = [Entry(p.stem, p, False) for p in lab]
    names = {e.name for e in out}
    out += [Entry(n, None, True) for n in bundled_names() if n not in names]
    return out


def find(name_or_path: str) -> ExtrusionProfile:
    """A profile by library name, bundled name or path."""
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.is_file():
        return load_profile(path)
    for entry in entries():
        if entry.name == name_or_path:
            return entry.load()
    known = ", ".join(e.name for e in entries())
    raise InputError(f"no profile '{name_or_path}'",
                     f"use one of {known} (`mesp profile list`) or a path to a profile .toml")


def active(cell: str) -> ExtrusionProfile:
    """The cell's active profile."""
    path = active_file(cell)
    return load_profile(path) if path.is_file() else load_profile(FACTORY)


def active_source(cell: str) -> str:
    """What the job's ``[extrusion] profile = "active"`` means on ``cell``: a path or a name."""
    path = active_file(cell)
    return str(path) if path.is_file() else FACTORY


def resolve(profile: str, cell: str) -> str:
    """A job's ``[extrusion] profile`` with ``ACTIVE`` replaced by the cell's active profile."""
    return active_source(cell) if profile == ACTIVE else profile


def activate(name_or_path: str, cell: str) -> ExtrusionProfile:
    """Make a profile ``cell``'s active one; a profile given by path joins the library too."""
    profile = find(name_or_path)
    if Path(name_or_path).suffix == ".toml" or Path(name_or_path).is_file():
        kept = library_dir() / f"{check_name(profile.name)}.toml"
        if kept.is_file() and load_profile(kept).sha256 != profile.sha256:
            raise InputError(f"the library already has a different profile '{profile.name}'",
                             f"rename the profile (its name = ...) or remove {kept}")
        atomic_write_bytes(kept, profile.text.encode())
    atomic_write_bytes(active_file(cell), profile.text.encode())
    return profile


def save(profile_text: str, name: str) -> Path:
    """Keep a new profile in the library as ``<name>.toml``; an existing name is refused."""
    path = library_dir() / f"{check_name(name)}.toml"
    if path.exists():
        raise InputError(f"profile {path} exists", "give another --name, or --out PATH")
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, profile_text.encode())
    return path


def stale_reason(job_profile: ExtrusionProfile, cell: str) -> str:
    """'' when a job's profile is ``cell``'s active calibration, else why it is not."""
    current = active(cell)
    if job_profile.sha256 == current.sha256:
        return ""
    return (f"sliced with extrusion profile '{job_profile.name}' ({job_profile.sha256[:12]}, "
            f"C {job_profile.rate_mm3_s:g} mm^3/s), but cell '{cell}' calibrates to "
            f"'{current.name}' ({current.sha256[:12]}, C {current.rate_mm3_s:g} mm^3/s)")


def describe(profile: ExtrusionProfile) -> str:
    """One line: name, C at its set-point, calibrated or not, short hash."""
    state = "calibrated" if profile.calibrated else "uncalibrated"
    return (f"{profile.name}: C {profile.rate_mm3_s:g} mm^3/s at set-point "
            f"{profile.setpoint_mm3_s:g} mm^3/s, {state}, sha256 {profile.sha256[:12]}")
