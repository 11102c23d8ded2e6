"""The ``trajectory.npz`` stage: a timed joint trajectory of the UR5e (design.md)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from core.artifacts import Schema
from core.stages import Stage


@dataclass(frozen=True, eq=False)
class Trajectory(Stage):
    """Samples of the planned motion, in time order.

    Attributes:
        t: (M,) float64, s, increasing from 0.
        q: (M, 6) float64, rad, joint positions.
        qd: (M, 6) float64, rad/s, joint velocities.
        tcp: (M, 3) float64, mm, nozzle tip in the robot base frame.
        waypoint: (M,) int32, toolpath waypoint index at this sample, -1 between waypoints.
        alpha: (M,) float64, deg, angle between nozzle axis and direction of motion.
        extrude: (M,) bool, the extruder deposits on the way to the next sample.
        base_T: (4, 4) float64, mm, robot base in the cell frame.
        tool_T: (4, 4) float64, mm, nozzle tip in the flange frame (z = nozzle axis, out of
            the tip).
        model_T: (4, 4) float64, mm, model frame -> robot base frame.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    tcp: np.ndarray
    waypoint: np.ndarray
    alpha: np.ndarray
    extrude: np.ndarray
    base_T: np.ndarray
    tool_T: np.ndarray
    model_T: np.ndarray

    FILE: ClassVar[str] = "trajectory.npz"
    SCHEMA: ClassVar[Schema] = {
        "t": (1, "f", None),
        "q": (2, "f", (6,)),
        "qd": (2, "f", (6,)),
        "tcp": (2, "f", (3,)),
        "waypoint": (1, "iu", None),
        "alpha": (1, "f", None),
        "extrude": (1, "b", None),
        "base_T": (2, "f", (4,)),
        "tool_T": (2, "f", (4,)),
        "model_T": (2, "f", (4,)),
    }
    DTYPES: ClassVar[dict[str, type]] = {
        "t": np.float64,
        "q": np.float64,
        "qd": np.float64,
        "tcp": np.float64,
        "waypoint": np.int32,
        "alpha": np.float64,
        "extrude": np.bool_,
        "base_T": np.float64,
        "tool_T": np.float64,
        "model_T": np.float64,
    }

    def __post_init__(self) -> None:
        self._freeze()
        M = len(self.t)
        for name in ("q", "qd", "tcp", "waypoint", "alpha", "extrude"):
            if len(getattr(self, name)) != M:
                raise ValueError(f"'{name}' has {len(getattr(self, name))} rows, expected {M}")
        for name in ("base_T", "tool_T", "model_T"):
            if getattr(self, name).shape != (4, 4):
                raise ValueError(f"'{name}' must be 4 x 4")
        if M > 1 and np.any(np.diff(self.t) <= 0):
            raise ValueError("t must increase")

    def __len__(self) -> int:
        return len(self.t)

    @property
    def duration_s(self) -> float:
        """Total time, s."""
        return float(self.t[-1]) if len(self.t) else 0.0
