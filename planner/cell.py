"""The cell description: robot base, tool, table, gel tank, model placement, planning limits.

Loaded from TOML (``planner/cells/default.toml`` is the bundled cell of the paper's Fig. 10)
into frozen dataclasses validated on construction; ``core.configtools.build`` turns every
bad value into an ``InputError`` naming the key. Lengths are mm and angles deg in the file and
in these dataclasses; ``*_T`` helpers give homogeneous transforms in mm.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Literal

import numpy as np

from core.alpha_range import AlphaRange
from core.configtools import build, merge, read_ranges, read_toml
from core.errors import InputError
from core.path_accel import PathAccel
from core.toml_defaults import table

# every field default below comes from the bundled cell, the one defaults file of a cell
_CELL = table("planner", "cells/default.toml")

Vec3 = tuple[float, float, float]


def _vec(value: tuple[float, ...], n: int, name: str) -> None:
    if len(value) != n:
        raise ValueError(f"{name} needs {n} numbers, got {len(value)}")


def rpy_matrix(rpy_rad: np.ndarray) -> np.ndarray:
    """Rotation matrix Rz(yaw) Ry(pitch) Rx(roll) of ``rpy_rad`` (3,) rad -> (3, 3)."""
    r, p, y = (float(v) for v in rpy_rad)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def pose(xyz_mm: tuple[float, ...], rpy_deg: tuple[float, ...] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Homogeneous transform (4, 4) float64, mm, from a position and roll-pitch-yaw in deg."""
    T = np.eye(4)
    T[:3, :3] = rpy_matrix(np.radians(rpy_deg))
    T[:3, 3] = xyz_mm
    return T


@dataclass(frozen=True)
class RobotConfig:
    """The UR5e: base pose in the cell, home pose and joint limits (deg, deg/s, deg/s^2)."""

    base_xyz_mm: Vec3 = _CELL["robot"]["base_xyz_mm"]
    base_rpy_deg: Vec3 = _CELL["robot"]["base_rpy_deg"]
    home_deg: tuple[float, ...] = _CELL["robot"]["home_deg"]
    joint_min_deg: tuple[float, ...] = _CELL["robot"]["joint_min_deg"]
    joint_max_deg: tuple[float, ...] = _CELL["robot"]["joint_max_deg"]
    max_velocity_deg_s: tuple[float, ...] = _CELL["robot"]["max_velocity_deg_s"]
    max_acceleration_deg_s2: tuple[float, ...] = _CELL["robot"]["max_acceleration_deg_s2"]
    link_radius_mm: tuple[float, ...] = _CELL["robot"]["link_radius_mm"]

    def __post_init__(self) -> None:
        _vec(self.base_xyz_mm, 3, "base_xyz_mm")
        _vec(self.base_rpy_deg, 3, "base_rpy_deg")
        for name in ("home_deg", "joint_min_deg", "joint_max_deg", "max_velocity_deg_s",
                     "max_acceleration_deg_s2", "link_radius_mm"):
            _vec(getattr(self, name), 6, name)
        lo, hi = np.array(self.joint_min_deg), np.array(self.joint_max_deg)
        if np.any(lo >= hi):
            raise ValueError("joint_min_deg must be below joint_max_deg for every joint")
        home = np.array(self.home_deg)
        if np.any(home < lo) or np.any(home > hi):
            raise ValueError("home_deg lies outside the joint limits")
        if min(self.max_velocity_deg_s) <= 0 or min(self.max_acceleration_deg_s2) <= 0:
            raise ValueError("max_velocity_deg_s and max_acceleration_deg_s2 must be positive")
        if min(self.link_radius_mm) <= 0:
            raise ValueError("link_radius_mm must be positive")

    @property
    def base_T(self) -> np.ndarray:
        """(4, 4) float64, mm: robot base in the cell frame."""
        return pose(self.base_xyz_mm, self.base_rpy_deg)


@dataclass(frozen=True)
class ToolPart:
    """A rigid part of the tool in the flange frame: a box or a cylinder along flange z.

    Attributes:
        name: label used in reports.
        shape: "box" (size = full extents x, y, z) or "cylinder" (size = diameter, diameter,
            length).
        center_mm: (3,) centre in the flange frame.
        size_mm: (3,) extents, see ``shape``.
    """

    name: str
    shape: Literal["box", "cylinder"]
    center_mm: Vec3
    size_mm: Vec3

    def __post_init__(self) -> None:
        _vec(self.center_mm, 3, f"{self.name}.center_mm")
        _vec(self.size_mm, 3, f"{self.name}.size_mm")
        if min(self.size_mm) <= 0:
            raise ValueError(f"tool part '{self.name}': size_mm must be positive")


@dataclass(frozen=True)
class ToolConfig:
    """Flange-to-nozzle-tip transform, the nozzle shaft and the holder/extruder parts."""

    tip_xyz_mm: Vec3 = _CELL["tool"]["tip_xyz_mm"]
    tip_rpy_deg: Vec3 = _CELL["tool"]["tip_rpy_deg"]
    nozzle_length_mm: float = _CELL["tool"]["nozzle_length_mm"]
    nozzle_diameter_mm: float = _CELL["tool"]["nozzle_diameter_mm"]
    parts: tuple[ToolPart, ...] = field(default_factory=lambda: tuple(
        ToolPart(**part) for part in _CELL["tool"]["parts"]))

    def __post_init__(self) -> None:
        _vec(self.tip_xyz_mm, 3, "tip_xyz_mm")
        _vec(self.tip_rpy_deg, 3, "tip_rpy_deg")
        if self.nozzle_length_mm <= 0 or self.nozzle_diameter_mm <= 0:
            raise ValueError("nozzle_length_mm and nozzle_diameter_mm must be positive")
        if self.nozzle_length_mm >= float(np.linalg.norm(self.tip_xyz_mm)):
            raise ValueError("nozzle_length_mm must be shorter than the flange-to-tip distance")

    @property
    def tool_T(self) -> np.ndarray:
        """(4, 4) float64, mm: nozzle tip in the flange frame."""
        return pose(self.tip_xyz_mm, self.tip_rpy_deg)


@dataclass(frozen=True)
class TableConfig:
    """The table the robot and the tank stand on: an axis-aligned box in the cell frame."""

    center_mm: Vec3 = _CELL["table"]["center_mm"]
    size_mm: Vec3 = _CELL["table"]["size_mm"]

    def __post_init__(self) -> None:
        _vec(self.center_mm, 3, "center_mm")
        _vec(self.size_mm, 3, "size_mm")
        if min(self.size_mm) <= 0:
            raise ValueError("size_mm must be positive")


@dataclass(frozen=True)
class TankConfig:
    """The gel tank: inner box, wall thickness (also the floor's), pose and gel fill height.

    ``gel_fill_mm`` is the highest fill; with ``fit_gel`` a job fills the tank only to
    ``gel_cover_mm`` above the top of its part (a short part then leaves the extruder body
    far above the gel), see ``planner.placement.fit_gel``.
    """

    floor_center_mm: Vec3 = _CELL["tank"]["floor_center_mm"]
    yaw_deg: float = _CELL["tank"]["yaw_deg"]
    inner_size_mm: Vec3 = _CELL["tank"]["inner_size_mm"]
    wall_mm: float = _CELL["tank"]["wall_mm"]
    gel_fill_mm: float = _CELL["tank"]["gel_fill_mm"]
    fit_gel: bool = _CELL["tank"]["fit_gel"]
    gel_cover_mm: float = _CELL["tank"]["gel_cover_mm"]

    def __post_init__(self) -> None:
        _vec(self.floor_center_mm, 3, "floor_center_mm")
        _vec(self.inner_size_mm, 3, "inner_size_mm")
        if min(self.inner_size_mm) <= 0 or self.wall_mm <= 0:
            raise ValueError("inner_size_mm and wall_mm must be positive")
        if not 0 < self.gel_fill_mm <= self.inner_size_mm[2]:
            raise ValueError("gel_fill_mm must lie in (0, inner height]")
        if self.gel_cover_mm < 0:
            raise ValueError("gel_cover_mm must be >= 0")

    @property
    def floor_T(self) -> np.ndarray:
        """(4, 4) float64, mm: inner floor centre of the tank in the cell frame (z up)."""
        return pose(self.floor_center_mm, (0.0, 0.0, self.yaw_deg))


@dataclass(frozen=True)
class PlacementConfig:
    """Where the model frame sits in the tank, and whether to search for a better place."""

    offset_mm: Vec3 = _CELL["placement"]["offset_mm"]
    yaw_deg: float = _CELL["placement"]["yaw_deg"]
    search: bool = _CELL["placement"]["search"]
    search_step_mm: float = _CELL["placement"]["search_step_mm"]
    search_yaw_step_deg: float = _CELL["placement"]["search_yaw_step_deg"]
    wall_margin_mm: float = _CELL["placement"]["wall_margin_mm"]

    def __post_init__(self) -> None:
        _vec(self.offset_mm, 3, "offset_mm")
        if self.search_step_mm <= 0 or not 0 < self.search_yaw_step_deg <= 360:
            raise ValueError("search_step_mm must be > 0 and search_yaw_step_deg in (0, 360]")
        if self.wall_margin_mm < 0:
            raise ValueError("wall_margin_mm must be >= 0")


@dataclass(frozen=True)
class PlanningConfig:
    """Orientation, clearance and timing settings of the planner."""

    alpha_min_deg: float = _CELL["planning"]["alpha_min_deg"]
    alpha_max_deg: float = _CELL["planning"]["alpha_max_deg"]
    lean_max_deg: float = _CELL["planning"]["lean_max_deg"]
    upright_max_deg: float = _CELL["planning"]["upright_max_deg"]
    smooth_length_mm: float = _CELL["planning"]["smooth_length_mm"]
    smooth_max_deg: float = _CELL["planning"]["smooth_max_deg"]
    clearance_mm: float = _CELL["planning"]["clearance_mm"]
    joint_margin_deg: float = _CELL["planning"]["joint_margin_deg"]
    singular_margin: float = _CELL["planning"]["singular_margin"]
    damping: float = _CELL["planning"]["damping"]
    spin_steps: int = _CELL["planning"]["spin_steps"]
    max_step_mm: float = _CELL["planning"]["max_step_mm"]
    travel_speed_mm_s: float = _CELL["planning"]["travel_speed_mm_s"]
    transfer_speed_mm_s: float = _CELL["planning"]["transfer_speed_mm_s"]
    approach_above_gel_mm: float = _CELL["planning"]["approach_above_gel_mm"]
    path_accel_mm_s2: float = _CELL["planning"]["path_accel_mm_s2"]
    path_turn_accel_rad_s2: float = _CELL["planning"]["path_turn_accel_rad_s2"]

    @property
    def alpha_range(self) -> AlphaRange:
        """The printing-angle range, as the slicer's step limits take it."""
        return AlphaRange(self.alpha_min_deg, self.alpha_max_deg)

    @property
    def path_accel(self) -> PathAccel:
        """The path accelerations, as the slicer's speed ramps take them."""
        return PathAccel(self.path_accel_mm_s2, self.path_turn_accel_rad_s2)

    def __post_init__(self) -> None:
        AlphaRange(self.alpha_min_deg, self.alpha_max_deg)  # validates the range
        if not 0 <= self.lean_max_deg <= 60:
            raise ValueError("lean_max_deg must lie in [0, 60]")
        if not 0 <= self.upright_max_deg <= 45:
            raise ValueError("upright_max_deg must lie in [0, 45]")
        if self.smooth_length_mm < 0 or not 0 <= self.smooth_max_deg <= 20:
            raise ValueError("need smooth_length_mm >= 0 and smooth_max_deg in [0, 20]")
        if self.clearance_mm < 0 or self.joint_margin_deg < 0:
            raise ValueError("clearance_mm and joint_margin_deg must be >= 0")
        if self.singular_margin <= 0 or self.damping < 0:
            raise ValueError("singular_margin must be > 0 and damping >= 0")
        if self.spin_steps < 4:
            raise ValueError("spin_steps must be at least 4")
        if self.max_step_mm <= 0 or self.travel_speed_mm_s <= 0:
            raise ValueError("max_step_mm and travel_speed_mm_s must be positive")
        if self.approach_above_gel_mm <= 0 or self.transfer_speed_mm_s <= 0:
            raise ValueError("approach_above_gel_mm and transfer_speed_mm_s must be positive")
        if self.path_accel_mm_s2 <= 0 or self.path_turn_accel_rad_s2 <= 0:
            raise ValueError("path_accel_mm_s2 and path_turn_accel_rad_s2 must be positive")


@dataclass(frozen=True)
class CellConfig:
    """A whole cell (see ``planner/cells/default.toml`` for every key)."""

    robot: RobotConfig = field(default_factory=RobotConfig)
    tool: ToolConfig = field(default_factory=ToolConfig)
    table: TableConfig = field(default_factory=TableConfig)
    tank: TankConfig = field(default_factory=TankConfig)
    placement: PlacementConfig = field(default_factory=PlacementConfig)
    planning: PlanningConfig = field(default_factory=PlanningConfig)

    @property
    def tank_in_base(self) -> np.ndarray:
        """(4, 4) float64, mm: inner floor centre of the tank in the robot base frame."""
        return np.linalg.inv(self.robot.base_T) @ self.tank.floor_T


def default_cell_data() -> dict:
    """The bundled default cell as parsed TOML."""
    text = resources.files("planner").joinpath("cells/default.toml").read_text()
    return tomllib.loads(text)


def load_cell(path: Path | None = None) -> CellConfig:
    """The bundled default cell, overridden key by key by the TOML file at ``path`` if given.

    Raises:
        InputError: the file is missing or malformed, or a key is unknown or has a bad value.
    """
    data = default_cell_data()
    if path is not None:
        user = read_toml(Path(path))
        if "extrusion_rate_mm3_s" in user.get("planning", {}):
            raise InputError(f"{path}: [planning] extrusion_rate_mm3_s is no cell setting: C "
                             "belongs to the extrusion profile the job is sliced with",
                             "delete the line; set C with `mesp calibrate extrusion`")
        # a user's tool.parts list replaces the default list as a whole (merge is per key)
        data = merge(data, user)
    ranges = read_ranges(resources.files("planner").joinpath("cell_ranges.toml").read_text(),
                         "planner/cell_ranges.toml")
    return build(CellConfig, data, "cell", ranges, "planner/cell_ranges.toml")
