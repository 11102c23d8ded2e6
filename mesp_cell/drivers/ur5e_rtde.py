"""The real UR5e over RTDE (ur-rtde, imported when the driver connects).

servoJ at 500 Hz inside ``initPeriod``/``waitPeriod``; ``servoStop`` is always called before any
other move (UR's controller refuses moveJ while a servo stream is active). A lost connection is
reported by ``connected()`` and ``servo_j`` returning False; the robot node then stops the print
and tries ``reconnect()``. A protective stop is read from the receive interface.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mesp_cell.drivers.robot_base import RobotLinkError, ServoConfig


class UR5eRTDE:
    """A UR5e at ``host``; ``tool_T`` (4, 4) float64, mm: nozzle tip in the flange frame."""

    def __init__(self, host: str, servo: ServoConfig, tool_T: np.ndarray | None = None) -> None:
        self.host = host
        self.servo = servo
        self.tool_T = np.eye(4) if tool_T is None else np.asarray(tool_T, dtype=np.float64)
        self._ctrl: Any = None
        self._recv: Any = None
        self._servoing = False

    def connect(self) -> None:
        """Open both RTDE interfaces; ``RobotLinkError`` (nothing left open) if the controller
        does not answer."""
        import rtde_control
        import rtde_receive

        freq = 1.0 / self.servo.dt
        try:
            self._ctrl = rtde_control.RTDEControlInterface(self.host, freq)
            self._recv = rtde_receive.RTDEReceiveInterface(self.host, freq)
            self._ctrl.setTcp(_pose_from_T(self.tool_T))
            # The controller stops the arm when this process stops kicking (crash, hang).
            self._ctrl.setWatchdog(self.servo.watchdog_hz)
        except RuntimeError as exc:  # ur-rtde raises RuntimeError for every link failure
            for iface in (self._ctrl, self._recv):
                try:
                    if iface is not None:
                        iface.disconnect()
                except RuntimeError:
                    pass
            self._ctrl = self._recv = None
            raise RobotLinkError(f"no RTDE connection to the UR5e at {self.host} ({exc})") from exc

    def kick_watchdog(self) -> None:
        if self._ctrl is not None and self._ctrl.isConnected():
            self._ctrl.kickWatchdog()

    def close(self) -> None:
        if self._ctrl is not None:
            self.servo_stop()
            self._ctrl.stopScript()
            self._ctrl.disconnect()
        if self._recv is not None:
            self._recv.disconnect()

    def reconnect(self) -> bool:
        ok = True
        if self._ctrl is not None and not self._ctrl.isConnected():
            ok = bool(self._ctrl.reconnect()) and ok
        if self._recv is not None and not self._recv.isConnected():
            ok = bool(self._recv.reconnect()) and ok
        return ok

    def connected(self) -> bool:
        return bool(self._ctrl is not None and self._ctrl.isConnected()
                    and self._recv is not None and self._recv.isConnected())

    def protective_stopped(self) -> bool:
        return bool(self._recv is not None and self._recv.isProtectiveStopped())

    def init_period(self) -> float:
        return float(self._ctrl.initPeriod())

    def wait_period(self, t_start: float) -> None:
        self._ctrl.waitPeriod(t_start)

    def servo_j(self, q: np.ndarray) -> bool:
        s = self.servo
        self._servoing = True
        return bool(self._ctrl.servoJ([float(v) for v in q], s.velocity, s.acceleration, s.dt,
                                      s.lookahead_s, s.gain))

    def servo_stop(self) -> None:
        if self._ctrl is not None and self._servoing:
            self._ctrl.servoStop(self.servo.stop_decel)
        self._servoing = False

    def move_j(self, q: np.ndarray) -> bool:
        self.servo_stop()
        return bool(self._ctrl.moveJ([float(v) for v in q], self.servo.move_speed,
                                     self.servo.move_accel, False))

    def stop_j(self) -> None:
        self.servo_stop()
        if self._ctrl is not None:
            self._ctrl.stopJ(self.servo.stop_decel)

    def joints(self) -> np.ndarray:
        return np.asarray(self._recv.getActualQ(), dtype=np.float64)

    def joint_speeds(self) -> np.ndarray:
        return np.asarray(self._recv.getActualQd(), dtype=np.float64)

    def tcp_mm(self) -> np.ndarray:
        return np.asarray(self._recv.getActualTCPPose()[:3], dtype=np.float64) * 1000.0


def _pose_from_T(T: np.ndarray) -> list[float]:
    """A 4x4 pose (mm) as UR's [x, y, z (m), rx, ry, rz (axis-angle, rad)]."""
    from scipy.spatial.transform import Rotation

    rv = Rotation.from_matrix(T[:3, :3]).as_rotvec()
    return [*(T[:3, 3] / 1000.0).tolist(), *rv.tolist()]
