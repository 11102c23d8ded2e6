"""The nozzle acceleration a toolpath may ask for where its speed changes within a path.

The slicer changes the nozzle speed inside a path where it changes the width (W = C / (H v)):
the stripe joins print narrower, so faster (``slicer.toolpath.stripe_joins``). The arm
reaches a speed change only as fast as its joint accelerations allow, and where the printing
direction turns along the path (a U-turn at the curved rim of a layer) the wrist turns with it,
so there far less than on a path that keeps its direction (``path_accel``). The values are cell
settings: they live in the cell file (``[planning] path_accel_mm_s2``,
``path_turn_accel_rad_s2``); the slicer receives the job's cell's as a ``PathAccel`` (``mesp
slice --cell``, the job's cell in the runtime; the bundled cell's by default) and shapes its
speed ramps to them, and the planner reports the toolpath segments that ask more than the
job's cell gives on a path that keeps its direction (``plan.path_accel`` in report.json,
``planner.flow.asked_acceleration``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core.tolerance import tol
from core.toml_defaults import table


@dataclass(frozen=True)
class PathAccel:
    """A cell's limits on speed changes along a path.

    Attributes:
        accel_mm_s2: mm/s^2, on a path that keeps its printing direction.
        turn_rad_s2: rad/s^2, the tool's turn acceleration where the direction turns.
    """

    accel_mm_s2: float
    turn_rad_s2: float

    def __post_init__(self) -> None:
        if not (self.accel_mm_s2 > 0 and self.turn_rad_s2 > 0):
            raise ValueError("path_accel_mm_s2 and path_turn_accel_rad_s2 must be positive")

    @staticmethod
    def bundled() -> PathAccel:
        """The bundled cell's (``planner/cells/default.toml``)."""
        return PathAccel(bundled_path_accel(), bundled_turn_accel())


def bundled_path_accel() -> float:
    """mm/s^2, the path acceleration of the bundled cell (``planner/cells/default.toml``)."""
    return float(table("planner", "cells/default.toml", "planning")["path_accel_mm_s2"])


def bundled_turn_accel() -> float:
    """rad/s^2, the bundled cell's tool turn acceleration: along a path whose printing
    direction turns by k rad/mm, a nozzle acceleration a turns the tool at k a rad/s^2, so
    the path acceleration there is at most this / k."""
    return float(table("planner", "cells/default.toml", "planning")["path_turn_accel_rad_s2"])


def path_accel(turn_rate: NDArray[np.float64], accel: float, turn_accel: float
               ) -> NDArray[np.float64]:
    """mm/s^2, the acceleration a speed change may ask for along paths whose printing
    direction turns by ``turn_rate`` (rad/mm, any shape): ``accel`` (mm/s^2) on a path that
    keeps its direction, ``turn_accel`` (rad/s^2) / turn_rate where that is less."""
    return np.minimum(accel, turn_accel / np.maximum(turn_rate, tol.zero))
