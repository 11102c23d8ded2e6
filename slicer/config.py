"""The print job's configuration: typed, validated, loaded from TOML over one defaults file."""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any, Literal

import numpy as np

from core.configtools import build, merge, read_ranges, read_toml
from core.errors import InputError
from core.toml_defaults import table

# every field default below comes from the one defaults file
_JOB = table("slicer", "defaults.toml")

UNIT_SCALE_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}

_SELECTOR = re.compile(
    r"^(?P<kind>bottom|top)(?::(?P<cone>[-+0-9.eE]+))?$"
    r"|^normal:(?P<n>[-+0-9.eE]+,[-+0-9.eE]+,[-+0-9.eE]+)(?::(?P<ncone>[-+0-9.eE]+))?$"
)
_WHERE = re.compile(r"^(?P<axis>[xyz])(?P<op>[<>])(?P<value>[-+0-9.eE]+)$")


@dataclass(frozen=True)
class CriticalSelector:
    """Boundary faces whose outward normal lies within ``cone_deg`` of ``direction``, in
    patches whose centre satisfies every condition of ``where``.

    Attributes:
        direction: (3,) float, unit axis of the cone.
        cone_deg: float, deg, half-angle of the cone.
        text: the selector as the user wrote it.
        where: ((axis 0-2, "<" or ">", value mm), ...): conditions on the area-weighted
            centre of each patch, in the model's frame (mm, as in model.ply); e.g.
            ``bottom:30@z<1`` keeps the bottom face but not a cavity's ceiling.
        at_end: ``@end``: only the patches that reach the part's end along the cone's axis
            (its lowest point for a bottom, its highest for a top; within ``END_TOLERANCE``
            of the part's extent along the axis): the face a user would call the bottom,
            not every downward-facing bump of a scan.
    """

    direction: tuple[float, float, float]
    cone_deg: float
    text: str
    where: tuple[tuple[int, str, float], ...] = ()
    at_end: bool = False

    def accepts(self, centre: np.ndarray) -> bool:
        """True if the point ``centre`` (3,) mm meets every ``where`` condition."""
        return all(centre[axis] < value if op == "<" else centre[axis] > value
                   for axis, op, value in self.where)

    @staticmethod
    def parse(text: str) -> CriticalSelector:
        """Parse ``bottom[:DEG]``, ``top[:DEG]`` or ``normal:X,Y,Z[:DEG]`` (default 45 deg),
        each optionally followed by position conditions ``@z<MM``, ``@x>MM``, ..."""
        fix = ("write bottom[:DEG], top[:DEG] or normal:X,Y,Z[:DEG], optionally with @z<MM "
               "(or @x, @y, >) or @end, e.g. top:30, bottom:30@z<1 or bottom:45@end")
        head, *conditions = text.strip().split("@")
        where = []
        at_end = any(c.strip() == "end" for c in conditions)
        for cond in (c for c in conditions if c.strip() != "end"):
            found = _WHERE.match(cond.strip())
            if found is None:
                raise InputError(f"critical selector '{text}': condition '@{cond}' is not "
                                 "understood", fix)
            try:
                value = float(found["value"])
            except ValueError as exc:
                raise InputError(f"critical selector '{text}' has a bad number", fix) from exc
            where.append(("xyz".index(found["axis"]), found["op"], value))
        match = _SELECTOR.match(head.strip())
        if match is None:
            raise InputError(f"critical selector '{text}' is not understood", fix)
        try:
            if match["kind"]:
                axis = (0.0, 0.0, -1.0) if match["kind"] == "bottom" else (0.0, 0.0, 1.0)
                cone = float(match["cone"]) if match["cone"] else 45.0
            else:
                vec = np.array([float(v) for v in match["n"].split(",")])
                norm = float(np.linalg.norm(vec))
                if norm == 0.0:
                    raise InputError(f"critical selector '{text}' has a zero normal", fix)
                axis = tuple(float(v) for v in vec / norm)  # type: ignore[assignment]
                cone = float(match["ncone"]) if match["ncone"] else 45.0
        except ValueError as exc:
            raise InputError(f"critical selector '{text}' has a bad number", fix) from exc
        if not 0.0 < cone < 90.0:
            raise InputError(f"critical selector '{text}': cone {cone} deg", "use 0 < DEG < 90")
        return CriticalSelector(direction=axis, cone_deg=cone, text=text.strip(),
                                where=tuple(where), at_end=at_end)


@dataclass(frozen=True)
class ModelConfig:
    units: Literal["mm", "cm", "m", "in"] = _JOB["model"]["units"]
    max_size_mm: float = _JOB["model"]["max_size_mm"]
    min_size_mm: float = _JOB["model"]["min_size_mm"]
    scale_to_mm: float = _JOB["model"]["scale_to_mm"]

    def __post_init__(self) -> None:
        if not 0 < self.min_size_mm < self.max_size_mm:
            raise ValueError("need 0 < min_size_mm < max_size_mm")
        if not (self.scale_to_mm == 0.0
                or self.min_size_mm <= self.scale_to_mm <= self.max_size_mm):
            raise ValueError("scale_to_mm must be 0 (off) or within [min_size_mm, max_size_mm]")

    @property
    def scale_mm(self) -> float:
        """Millimetres per model-file unit."""
        return UNIT_SCALE_MM[self.units]


MAX_REFINE = 3  # red refinements after fTetWild (each multiplies the tets by 8)


@dataclass(frozen=True)
class MeshConfig:
    edge_length_mm: float = _JOB["mesh"]["edge_length_mm"]
    epsilon: float = _JOB["mesh"]["epsilon"]
    stop_energy: float = _JOB["mesh"]["stop_energy"]
    optimize_iterations: int = _JOB["mesh"]["optimize_iterations"]
    coarsen: bool = _JOB["mesh"]["coarsen"]
    refine: int | Literal["auto"] = _JOB["mesh"]["refine"]

    def __post_init__(self) -> None:
        if self.refine != "auto" and self.refine not in range(MAX_REFINE + 1):
            raise ValueError(f"refine = {self.refine!r}, use \"auto\" or 0 to {MAX_REFINE}")
        if not 0.05 <= self.edge_length_mm <= 100.0:
            raise ValueError(f"edge_length_mm = {self.edge_length_mm}, use 0.05 to 100")
        if not 0 < self.epsilon < 0.1:
            raise ValueError(f"epsilon = {self.epsilon}, use 0 < epsilon < 0.1")
        if self.stop_energy <= 3.0:
            raise ValueError("stop_energy must exceed 3 (the energy of a regular tet)")
        if self.optimize_iterations < 0:
            raise ValueError("optimize_iterations must be >= 0")


@dataclass(frozen=True)
class SlicingConfig:
    layer_height_mm: float = _JOB["slicing"]["layer_height_mm"]
    critical: tuple[str, ...] = _JOB["slicing"]["critical"]
    planar: bool = _JOB["slicing"]["planar"]
    max_iterations: int = _JOB["slicing"]["max_iterations"]
    convergence: float = _JOB["slicing"]["convergence"]
    smoothness_weight: float = _JOB["slicing"]["smoothness_weight"]

    def __post_init__(self) -> None:
        if not 0.01 <= self.layer_height_mm <= 20.0:
            raise ValueError(f"layer_height_mm = {self.layer_height_mm}, use 0.01 to 20")
        for text in self.critical:
            CriticalSelector.parse(text)
        if self.max_iterations < 0:
            raise ValueError("max_iterations must be >= 0")
        if not 0 < self.convergence < 1:
            raise ValueError("convergence must be in (0, 1)")
        if self.smoothness_weight <= 0:
            raise ValueError("smoothness_weight must be > 0")

    @property
    def selectors(self) -> tuple[CriticalSelector, ...]:
        """The parsed critical-region selectors."""
        return tuple(CriticalSelector.parse(t) for t in self.critical)


@dataclass(frozen=True)
class ToolpathConfig:
    first_pattern: Literal["contour", "stripe"] = _JOB["toolpath"]["first_pattern"]
    waypoint_spacing: float = _JOB["toolpath"]["waypoint_spacing"]
    deformation_iterations: int = _JOB["toolpath"]["deformation_iterations"]
    deformation_tolerance: float = _JOB["toolpath"]["deformation_tolerance"]
    volume_tolerance: float = _JOB["toolpath"]["volume_tolerance"]
    min_path_length_mm: float = _JOB["toolpath"]["min_path_length_mm"]
    join_factor: float = _JOB["toolpath"]["join_factor"]
    spiral_rings: bool = _JOB["toolpath"]["spiral_rings"]
    narrow_joins: bool = _JOB["toolpath"]["narrow_joins"]
    fit_bands: bool = _JOB["toolpath"]["fit_bands"]
    fit_ridge: bool = _JOB["toolpath"]["fit_ridge"]
    pitch_width: bool = _JOB["toolpath"]["pitch_width"]
    flush: bool = _JOB["toolpath"]["flush"]
    stripe_perimeter: bool = _JOB["toolpath"]["stripe_perimeter"]
    first_layer_beta: float = _JOB["toolpath"]["first_layer_beta"]
    boundary_distance: Literal["eikonal", "heat"] = _JOB["toolpath"]["boundary_distance"]
    stripe_field: Literal["across", "parallel"] = _JOB["toolpath"]["stripe_field"]
    measure_baselines: bool = _JOB["toolpath"]["measure_baselines"]
    relieve_bends: bool = _JOB["toolpath"]["relieve_bends"]
    thin_walls: Literal["refuse", "thicken"] = _JOB["toolpath"]["thin_walls"]

    def __post_init__(self) -> None:
        if self.boundary_distance not in ("eikonal", "heat"):
            raise ValueError("boundary_distance must be 'eikonal' or 'heat'")
        if self.thin_walls not in ("refuse", "thicken"):
            raise ValueError("thin_walls must be 'refuse' or 'thicken'")
        if self.stripe_field not in ("across", "parallel"):
            raise ValueError("stripe_field must be 'across' or 'parallel'")
        if not 1.0 <= self.join_factor <= 20.0:
            raise ValueError("join_factor must be in [1, 20] (connector length / W)")
        if not 0.02 <= self.waypoint_spacing <= 2.0:
            raise ValueError("waypoint_spacing must be in [0.02, 2] (fraction of W)")
        if self.deformation_iterations < 0:
            raise ValueError("deformation_iterations must be >= 0")
        if not 0.0 <= self.deformation_tolerance <= 0.2:
            raise ValueError("deformation_tolerance must be in [0, 0.2] (relative scale error)")
        if not 0 < self.volume_tolerance < 0.2:
            raise ValueError("volume_tolerance must be in (0, 0.2)")
        if self.min_path_length_mm < 0:
            raise ValueError("min_path_length_mm must be >= 0")
        if self.first_layer_beta != 0.0 and not 0.3 <= self.first_layer_beta <= 1.0:
            raise ValueError("first_layer_beta must be 0 (the profile's beta) or in [0.3, 1]")


_PROFILE_NAME = re.compile(r"^[a-z0-9][a-z0-9._-]{0,63}$")


@dataclass(frozen=True)
class ExtrusionConfig:
    """The extrusion profile: "active" (the cell's active profile, resolved when the job is
    sliced), a profile name (the lab's library or ``slicer/profiles/NAME.toml``) or the path of
    a profile ``.toml``; nothing else is read (a name cannot leave the profiles folder)."""

    profile: str = _JOB["extrusion"]["profile"]

    def __post_init__(self) -> None:
        if self.profile.endswith(".toml") and len(self.profile) <= 4096:
            return
        if not _PROFILE_NAME.match(self.profile) or self.profile.endswith(".toml"):
            raise ValueError(f"profile = {self.profile!r} is neither a bundled profile name "
                             "nor a path ending in .toml; name one (e.g. ecoflex-0030) or give "
                             "a profile .toml")


@dataclass(frozen=True)
class JobConfig:
    """A whole print job's settings (see ``slicer/defaults.toml`` for every key)."""

    model: ModelConfig = field(default_factory=ModelConfig)
    mesh: MeshConfig = field(default_factory=MeshConfig)
    slicing: SlicingConfig = field(default_factory=SlicingConfig)
    toolpath: ToolpathConfig = field(default_factory=ToolpathConfig)
    extrusion: ExtrusionConfig = field(default_factory=ExtrusionConfig)

    def with_overrides(self, **sections: dict[str, Any]) -> JobConfig:
        """A new config with some keys of some sections replaced, validated again."""
        data = {name: vars_of(getattr(self, name)) for name in sections}
        ranges = job_ranges()
        out = self
        for name, changes in sections.items():
            merged = {**data[name], **changes}
            section_cls = type(getattr(self, name))
            own = {k[len(name) + 1:]: v for k, v in ranges.items() if k.startswith(f"{name}.")}
            out = replace(out, **{name: build(section_cls, merged, name, own, RANGES_FILE)})
        return out


def vars_of(section: Any) -> dict[str, Any]:
    """A config section's fields as a dict."""
    return {k: getattr(section, k) for k in section.__dataclass_fields__}


def default_data() -> dict[str, Any]:
    """The parsed defaults file."""
    text = resources.files("slicer").joinpath("defaults.toml").read_text()
    import tomllib

    return tomllib.loads(text)


RANGES_FILE = "slicer/ranges.toml"


def job_ranges() -> dict[str, tuple[float, float]]:
    """The accepted range of every number of a job (``slicer/ranges.toml``)."""
    text = resources.files("slicer").joinpath("ranges.toml").read_text()
    return read_ranges(text, RANGES_FILE)


def load_job(path: Path | None = None) -> JobConfig:
    """The defaults, overridden by the job file at ``path`` if given; every number finite and
    within its range (``slicer/ranges.toml``), the extrusion profile readable."""
    from slicer.extrusion import load_profile

    data = default_data()
    if path is not None:
        data = merge(data, read_toml(path))
    job = build(JobConfig, data, "job", job_ranges(), RANGES_FILE)
    load_profile(job.extrusion.profile)  # read and checked now, not after the tet mesh
    return job
