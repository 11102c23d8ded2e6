"""The MuJoCo twin of the cell: forward kinematics, geom distances and trajectory replay.

Built from the cell description (``sim.cell_mjcf``). Positions reported in mm in the robot base
frame, like ``trajectory.npz``; joint angles in rad.
"""

from __future__ import annotations

import importlib
import os
import sys
from dataclasses import dataclass
from types import ModuleType

import numpy as np

from planner import kinematics as kin
from planner.cell import CellConfig
from planner.trajectory import Trajectory
from sim.cell_mjcf import JOINT_NAMES, cell_mjcf


def _import_mujoco() -> tuple[ModuleType, str]:
    """Import mujoco; if the GL backend named by MUJOCO_GL cannot load, import it without one.

    Returns the module and a message naming the failed backend ("" if none failed), so
    simulation keeps working and rendering can explain why it is unavailable.
    """
    try:
        return importlib.import_module("mujoco"), ""
    except (AttributeError, ImportError, OSError) as exc:
        backend = os.environ.pop("MUJOCO_GL", None)
        if backend is None:
            raise
        for name in [m for m in sys.modules if m.split(".")[0] in ("mujoco", "OpenGL")]:
            del sys.modules[name]
        module = importlib.import_module("mujoco")
        return module, f"MUJOCO_GL={backend} could not be loaded ({type(exc).__name__}: {exc})"


mujoco, GL_PROBLEM = _import_mujoco()



@dataclass(frozen=True)
class Replay:
    """A trajectory played on the twin's actuators.

    Attributes:
        t: (K,) float64, s, simulation times of the records.
        q: (K, 6) float64, rad, simulated joint positions.
        tcp: (K, 3) float64, mm, simulated nozzle tip in the robot base frame.
        tcp_ref: (K, 3) float64, mm, the commanded TCP: planner FK of the interpolated q.
        error_mm: (K,) float64, |tcp - tcp_ref|.
    """

    t: np.ndarray
    q: np.ndarray
    tcp: np.ndarray
    tcp_ref: np.ndarray
    error_mm: np.ndarray


class Twin:
    """A MuJoCo model and data of one cell."""

    def __init__(self, cell: CellConfig, **mjcf_options: float) -> None:
        self.cell = cell
        self.xml = cell_mjcf(cell, **mjcf_options)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(self.model)
        self.qadr = np.array(
            [self.model.jnt_qposadr[self.model.joint(n).id] for n in JOINT_NAMES]
        )
        self.dadr = np.array([self.model.jnt_dofadr[self.model.joint(n).id] for n in JOINT_NAMES])
        self.tcp_site = self.model.site("tcp").id
        self.base_inv = np.linalg.inv(cell.robot.base_T)
        self.set_q(np.radians(cell.robot.home_deg))

    def set_q(self, q: np.ndarray) -> None:
        """Place the arm at ``q`` (6,) rad (zero velocity) and update the kinematics."""
        self.data.qpos[self.qadr] = q
        self.data.qvel[:] = 0.0
        self.data.ctrl[:6] = q
        self.data.ctrl[6:] = 0.0
        mujoco.mj_kinematics(self.model, self.data)

    def tcp_mm(self) -> np.ndarray:
        """Nozzle tip (3,) mm in the robot base frame at the current state."""
        p = np.append(self.data.site_xpos[self.tcp_site] * 1000.0, 1.0)
        return (self.base_inv @ p)[:3]

    def tcp_pose(self) -> np.ndarray:
        """Nozzle tip pose (4, 4) mm in the robot base frame at the current state."""
        T = np.eye(4)
        T[:3, :3] = self.data.site_xmat[self.tcp_site].reshape(3, 3)
        T[:3, 3] = self.data.site_xpos[self.tcp_site] * 1000.0
        return self.base_inv @ T

    def fk_mm(self, q: np.ndarray) -> np.ndarray:
        """TCP positions (S, 3) mm for configurations ``q`` (S, 6) (one mj_kinematics each)."""
        out = np.empty((len(q), 3))
        for i, qi in enumerate(np.asarray(q, dtype=float)):  # test/diagnostic use only
            self.set_q(qi)
            out[i] = self.tcp_mm()
        return out

    def geom_distance(self, q: np.ndarray, geom1: str, geom2: str, distmax: float = 1.0) -> float:
        """Signed distance (mm) between two named geoms at ``q`` (mujoco.mj_geomDistance)."""
        self.set_q(q)
        fromto = np.zeros(6)
        d = mujoco.mj_geomDistance(
            self.model, self.data, self.model.geom(geom1).id, self.model.geom(geom2).id,
            distmax, fromto,
        )
        return float(d) * 1000.0

    def replay(self, traj: Trajectory, record_every: int = 10, settle_s: float = 0.0) -> Replay:
        """Play ``traj`` on the position (q) and velocity (qd) actuators; record the TCP.

        The references are linearly interpolated at every physics step (a loop over time
        steps: the twin is a simulator, not a hot path of the planner).
        """
        self.set_q(traj.q[0])
        dt = self.model.opt.timestep
        steps = int(np.ceil((traj.duration_s + settle_s) / dt))
        ts, qs, tcps = [], [], []
        for k in range(steps + 1):
            tk = k * dt
            qref = np.array([np.interp(tk, traj.t, traj.q[:, j]) for j in range(6)])
            qdref = np.array([np.interp(tk, traj.t, traj.qd[:, j]) for j in range(6)])
            self.data.ctrl[:6] = qref
            self.data.ctrl[6:] = qdref
            if k % record_every == 0:
                mujoco.mj_kinematics(self.model, self.data)
                ts.append(tk)
                qs.append(self.data.qpos[self.qadr].copy())
                tcps.append(self.tcp_mm())
            mujoco.mj_step(self.model, self.data)
        t = np.array(ts)
        qref_all = np.stack([np.interp(t, traj.t, traj.q[:, j]) for j in range(6)], axis=1)
        tool = traj.tool_T.copy()
        tool[:3, 3] /= 1000.0
        ref = kin.fk(qref_all, tool)[:, :3, 3] * 1000.0
        tcp = np.array(tcps)
        return Replay(t, np.array(qs), tcp, ref, np.linalg.norm(tcp - ref, axis=1))
