"""What every robot driver provides (the UR5e over RTDE, and the twin backends).

Joint values are rad and rad/s; the TCP is in mm in the robot base frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class ServoConfig:
    """servoJ parameters (UR RTDE semantics).

    Attributes:
        dt: s, servo period (0.002 = 500 Hz). lookahead_s: s, in [0.03, 0.2], smooths the path.
        gain: proportional gain, in [100, 2000]. velocity: rad/s and acceleration: rad/s^2
        passed to servoJ (the controller ignores them for servoJ in current firmware).
        stop_decel: rad/s^2, deceleration of servoStop/stopJ.
        move_speed: rad/s and move_accel: rad/s^2 of point-to-point moves (home, approach, park).
        time_scale: the twin runs this many times faster than real time (1 = real time).
        realtime_priority: SCHED_FIFO priority (1-99) of the servo loop thread while it
            streams, 0 = normal scheduling. A loaded host needs it for sub-ms period jitter.
        watchdog_hz: the controller stops the arm if the host kicks its watchdog less often
            than this (RTDE setWatchdog; the robot node kicks it at its state rate).
        overrun_s: s, a servo period longer than this stops the stream (host loop stalled).
    """

    dt: float = 0.002
    lookahead_s: float = 0.1
    gain: float = 300.0
    velocity: float = 0.5
    acceleration: float = 0.5
    stop_decel: float = 10.0
    move_speed: float = 1.0
    move_accel: float = 1.4
    time_scale: float = 1.0
    realtime_priority: int = 0
    watchdog_hz: float = 10.0
    overrun_s: float = 0.1

    def __post_init__(self) -> None:
        if not 0.001 <= self.dt <= 0.1:
            raise ValueError(f"servo dt {self.dt} s outside [0.001, 0.1]")
        if not 0.03 <= self.lookahead_s <= 0.2:
            raise ValueError(f"lookahead {self.lookahead_s} s outside [0.03, 0.2]")
        if not 100 <= self.gain <= 2000:
            raise ValueError(f"servo gain {self.gain} outside [100, 2000]")
        if not 0 <= self.realtime_priority <= 99:
            raise ValueError(f"realtime_priority {self.realtime_priority} outside [0, 99]")
        if self.time_scale <= 0 or self.move_speed <= 0 or self.move_accel <= 0:
            raise ValueError("time_scale, move_speed and move_accel must be > 0")


class RobotLinkError(RuntimeError):
    """The robot controller does not answer (connect) or the link broke."""


class RobotDriver(Protocol):
    """A 6-axis arm driven by servoJ at a fixed period."""

    servo: ServoConfig

    def connect(self) -> None: ...

    def close(self) -> None: ...

    def reconnect(self) -> bool: ...

    def init_period(self) -> float: ...

    def wait_period(self, t_start: float) -> None: ...

    def servo_j(self, q: np.ndarray) -> bool: ...

    def servo_stop(self) -> None: ...

    def move_j(self, q: np.ndarray) -> bool: ...

    def stop_j(self) -> None: ...

    def joints(self) -> np.ndarray: ...

    def joint_speeds(self) -> np.ndarray: ...

    def tcp_mm(self) -> np.ndarray: ...

    def connected(self) -> bool: ...

    def protective_stopped(self) -> bool: ...

    def kick_watchdog(self) -> None: ...


# UR5e joint limits: position +-360 deg on every joint, speed 180 deg/s on every joint.
UR5E_Q_LIMIT = 2 * np.pi
UR5E_QD_LIMIT = np.pi
# UR5e standard DH parameters (m, rad), from Universal Robots' published kinematics.
UR5E_D = np.array([0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996])
UR5E_A = np.array([0.0, -0.425, -0.3922, 0.0, 0.0, 0.0])
UR5E_ALPHA = np.array([np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0])


def ur5e_flange(q: np.ndarray) -> np.ndarray:
    """Flange poses of the UR5e for joint vectors ``q``.

    Args:
        q: (..., 6) float64, rad.
    Returns:
        (..., 4, 4) float64, flange pose in the base frame, translation in mm.
    """
    q = np.asarray(q, dtype=np.float64)
    shape = q.shape[:-1]
    T = np.broadcast_to(np.eye(4), (*shape, 4, 4)).copy()
    ca, sa = np.cos(UR5E_ALPHA), np.sin(UR5E_ALPHA)
    for i in range(6):  # a loop over the 6 joints; each step is vectorised over all poses
        ct, st = np.cos(q[..., i]), np.sin(q[..., i])
        A = np.zeros((*shape, 4, 4))
        A[..., 0, 0], A[..., 0, 1], A[..., 0, 2], A[..., 0, 3] = ct, -st * ca[i], st * sa[i], \
            UR5E_A[i] * ct
        A[..., 1, 0], A[..., 1, 1], A[..., 1, 2], A[..., 1, 3] = st, ct * ca[i], -ct * sa[i], \
            UR5E_A[i] * st
        A[..., 2, 1], A[..., 2, 2], A[..., 2, 3] = sa[i], ca[i], UR5E_D[i]
        A[..., 3, 3] = 1.0
        T = T @ A
    T[..., :3, 3] *= 1000.0
    return T
