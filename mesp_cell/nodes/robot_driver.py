"""The robot node's arm driver, from its launch parameters: the twin, MuJoCo or the UR5e.

The cell file is the one source of the home pose and the tool; a launch file may override
them (``home_deg``, ``tool_T``). The twin backends share the simulated cell's clock with the
emulated extruder (``sim_clock``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from mesp_cell.drivers.robot_base import RobotDriver, ServoConfig
from planner.cell import CellConfig, load_cell


def cell_of(params: dict[str, Any]) -> CellConfig:
    """The cell description of this robot: ``params['cell_file']`` ("" = the bundled cell)."""
    cell = cell_file_of(params)
    return load_cell(Path(cell) if cell else None)


def home_and_tool(params: dict[str, Any], cell: CellConfig) -> tuple[np.ndarray, np.ndarray]:
    """Home (6,) rad and tool (4, 4) mm: the cell's, unless the launch file overrides them
    (``home_deg``, ``tool_T``)."""
    home = np.radians(params.get("home_deg", cell.robot.home_deg))
    tool = params.get("tool_T")
    tool_T = cell.tool.tool_T if tool is None else np.asarray(tool, dtype=np.float64)
    return home, tool_T


def make_driver(params: dict[str, Any], servo: ServoConfig,
                cell: CellConfig | None = None) -> RobotDriver:
    """The driver named by ``params['backend']``: "twin" (default), "mujoco" or "ur5e"."""
    backend = params.get("backend", "twin")
    home, tool_T = home_and_tool(params, cell if cell is not None else cell_of(params))
    if backend in ("twin", "mujoco"):
        from mesp_cell.drivers.sim_clock import SimClock

        # the simulated cell's clock, shared with the emulated extruder ("" = private)
        clock = SimClock(servo.time_scale, params.get("sim_clock") or None)
    if backend == "twin":
        from mesp_cell.drivers.robot_twin import KinematicTwin

        return KinematicTwin(servo, q0=home, tool_T=tool_T, clock=clock)
    if backend == "mujoco":
        from mesp_cell.drivers.robot_twin import mujoco_twin

        return mujoco_twin(servo, q0=home, tool_T=tool_T, cell_file=cell_file_of(params),
                           clock=clock)
    if backend == "ur5e":
        from mesp_cell.drivers.ur5e_rtde import UR5eRTDE

        return UR5eRTDE(str(params["host"]), servo, tool_T=tool_T)
    raise ValueError(f"unknown robot backend '{backend}' (twin, mujoco, ur5e)")


def cell_file_of(params: dict[str, Any]) -> str | None:
    """The cell file of the MuJoCo backend (None = the bundled cell)."""
    cell = params.get("cell_file")
    return str(cell) if cell else None
