"""Twin backends of the robot driver: the same interface as the UR5e, no hardware.

``KinematicTwin`` integrates the commanded joint positions with a first-order servo response
(time constant ``lookahead_s * 75 / gain``: 25 ms at the defaults, a model of servoJ's
smoothing), clamped to the UR5e joint speed limit. ``MujocoTwin`` steps the MuJoCo model of
``sim.twin`` (position + velocity actuators) instead. Both keep simulated time (real time
scaled by ``servo.time_scale``, on the clock they share with the emulated extruder,
``sim_clock.SimClock``) in ``init_period``/``wait_period``, and both can be made to fail
(protective stop, link loss) for the safety tests.
"""

from __future__ import annotations

import threading
import time

import numpy as np

from mesp_cell.drivers.robot_base import UR5E_QD_LIMIT, ServoConfig, ur5e_flange
from mesp_cell.drivers.sim_clock import SimClock, clock_for

HOME_Q = np.deg2rad([0.0, -90.0, 90.0, -90.0, -90.0, 0.0])
HOLD_KEY = "twin"  # the twin's hold on the shared clock (``SimClock.hold``)


def precise_sleep_until(deadline: float) -> None:
    """Sleep until ``time.monotonic()`` reaches ``deadline``: coarse sleep, then a short spin.

    The final 0.3 ms spins so the 500 Hz loop's period jitter stays well under 0.5 ms.
    """
    remaining = deadline - time.monotonic()
    if remaining > 0.0003:
        time.sleep(remaining - 0.0003)
    while time.monotonic() < deadline:
        pass


class KinematicTwin:
    """A UR5e twin that integrates servo targets kinematically.

    Args:
        servo: servo parameters. q0: (6,) float64, rad, initial joints (home by default).
        tool_T: (4, 4) float64, mm, nozzle tip in the flange frame.
    """

    def __init__(self, servo: ServoConfig, q0: np.ndarray | None = None,
                 tool_T: np.ndarray | None = None, clock: SimClock | None = None) -> None:
        self.servo = servo
        self.clock = clock_for(servo.time_scale, clock)
        self._sim: float | None = None  # s, simulated time of the current motion
        self.q = np.array(HOME_Q if q0 is None else q0, dtype=np.float64)
        self.qd = np.zeros(6)
        self.tool_T = np.eye(4) if tool_T is None else np.asarray(tool_T, dtype=np.float64)
        self._connected = False
        self._pstop = False
        self._lock = threading.Lock()
        self.stop_times: list[float] = []  # time.time() of every servo_stop/stop_j
        self.commands = 0

    # -- link ------------------------------------------------------------------------------
    def connect(self) -> None:
        self._connected = True

    def close(self) -> None:
        self._connected = False

    def reconnect(self) -> bool:
        self._connected = True
        return True

    def connected(self) -> bool:
        return self._connected

    def protective_stopped(self) -> bool:
        return self._pstop

    def inject_protective_stop(self) -> None:
        """Make the twin refuse motion as a real controller does after a protective stop."""
        self._pstop = True

    def clear_protective_stop(self) -> None:
        self._pstop = False

    def inject_link_loss(self) -> None:
        self._connected = False

    def kick_watchdog(self) -> None:
        """The twin dies with its process, so there is nothing to stop on a missed kick."""

    # -- timing ----------------------------------------------------------------------------
    #: A period shorter than this (a fast twin) is not slept precisely: the loop runs ahead of
    #: the clock and sleeps only once it is this far ahead, releasing the GIL and the CPU
    #: instead of spinning (at 40x a period is 50 us, below the spin threshold, and a spinning
    #: servo thread starved the node's bus callbacks and the other processes).
    BATCH_S = 0.001

    def init_period(self) -> float:
        return self.clock.wall()

    def wait_period(self, t_start: float) -> None:
        """End one servo period: the twin's simulated time advances by ``servo.dt``.

        The period ends when the simulated clock reaches the twin's time. A twin behind the
        clock (its loop cannot keep ``time_scale``) does not race to catch up: it pauses the
        clock instead, so the extruder emulator's flow, counted on the same clock, waits for
        the arm. And the clock is held at the twin's time until the next period (for
        ``servo.overrun_s`` at most, when the servo watchdog stops a stream anyway), so a
        twin stalled mid-period stops the extruder's simulated time at once, not only after
        it runs again (``sim_clock``). Simulated time thus stays the twin's own
        ``periods x dt`` during a motion.
        """
        clock = self.clock
        sim = clock.now(t_start) if self._sim is None else self._sim  # a motion starts now
        self._sim = sim + self.servo.dt
        due = clock.wall_at(self._sim)
        now = clock.wall()
        clock.hold(HOLD_KEY, self._sim, self.servo.overrun_s, pause_s=now - due)
        if now > due:
            return
        if self.servo.dt / self.servo.time_scale >= self.BATCH_S:
            precise_sleep_until(due)  # real time (or nearly): a precise period, low jitter
        elif due - now > self.BATCH_S:
            time.sleep(due - now)

    def sim_now(self) -> float:
        """s, the twin's own simulated time: where its motion has got to (the shared clock's
        time at rest). What the servo loop decides (an extruder switch) happens at this time,
        also while an earlier switch holds the shared clock back (``extruder_switch``)."""
        sim = self._sim
        return self.clock.now() if sim is None else sim

    def end_motion(self) -> None:
        """The arm rests: simulated time runs with the clock until the next motion."""
        self._sim = None
        self.clock.release(HOLD_KEY)

    # -- motion ----------------------------------------------------------------------------
    def _step(self, target: np.ndarray, dt: float) -> None:
        tau = self.servo.lookahead_s * 75.0 / self.servo.gain
        step = (target - self.q) * min(1.0, dt / tau)
        step = np.clip(step, -UR5E_QD_LIMIT * dt, UR5E_QD_LIMIT * dt)
        self.qd = step / dt
        self.q = self.q + step

    def servo_j(self, q: np.ndarray) -> bool:
        if not self._connected or self._pstop:
            return False
        with self._lock:
            self._step(np.asarray(q, dtype=np.float64), self.servo.dt)
            self.commands += 1
        return True

    def servo_stop(self) -> None:
        with self._lock:
            self.qd = np.zeros(6)
            self.stop_times.append(time.time())
        self.end_motion()

    def stop_j(self) -> None:
        self.servo_stop()

    def move_j(self, q: np.ndarray) -> bool:
        """Point-to-point move at ``servo.move_speed`` (blocking, time-scaled)."""
        if not self._connected or self._pstop:
            return False
        target = np.asarray(q, dtype=np.float64)
        dist = float(np.max(np.abs(target - self.q)))
        duration = max(dist / self.servo.move_speed, self.servo.dt)
        n = max(1, int(np.ceil(duration / self.servo.dt)))
        start = self.q.copy()
        s = 0.5 - 0.5 * np.cos(np.linspace(0.0, np.pi, n + 1)[1:])  # smooth in/out
        try:
            for k in range(n):  # a loop over servo periods: each is one controller cycle
                t0 = self.init_period()
                if self._pstop or not self._connected:
                    return False
                with self._lock:
                    self._place(start + s[k] * (target - start))
                self.wait_period(t0)
        finally:
            self.end_motion()
        with self._lock:
            self.qd = np.zeros(6)
        return True

    def _place(self, q: np.ndarray) -> None:
        """One period of a point-to-point move: the kinematic twin follows it exactly."""
        self.q = q

    # -- state -----------------------------------------------------------------------------
    def joints(self) -> np.ndarray:
        return self.q.copy()

    def joint_speeds(self) -> np.ndarray:
        return self.qd.copy()

    def tcp_mm(self) -> np.ndarray:
        return np.asarray((ur5e_flange(self.q) @ self.tool_T)[:3, 3])


class MujocoTwin(KinematicTwin):
    """The twin on MuJoCo physics (``sim.twin.Twin``): servo targets drive the model's
    position actuators, with the target's finite-difference rate on its velocity actuators,
    stepped for one servo period per ``servo_j``. Timing, faults and the interface are the
    kinematic twin's; joints, speeds and the TCP are read from the simulation."""

    def __init__(self, servo: ServoConfig, q0: np.ndarray | None = None,
                 tool_T: np.ndarray | None = None, cell_file: str | None = None,
                 clock: SimClock | None = None) -> None:
        from pathlib import Path

        from planner.cell import load_cell
        from sim.twin import Twin, mujoco

        super().__init__(servo, q0=q0, tool_T=tool_T, clock=clock)
        self._mj = mujoco
        self.sim = Twin(load_cell(Path(cell_file) if cell_file else None))
        self.sim.set_q(self.q)
        self._substeps = max(1, round(servo.dt / float(self.sim.model.opt.timestep)))
        self._prev = self.q.copy()

    def _drive(self, target: np.ndarray, dt: float) -> None:
        d = self.sim.data
        d.ctrl[:6] = target
        d.ctrl[6:12] = (target - self._prev) / dt
        self._prev = target.copy()
        for _ in range(self._substeps):  # physics steps of one servo period
            self._mj.mj_step(self.sim.model, d)
        self.q = d.qpos[self.sim.qadr].copy()
        self.qd = d.qvel[self.sim.dadr].copy()

    def _step(self, target: np.ndarray, dt: float) -> None:
        self._drive(target, dt)

    def _place(self, q: np.ndarray) -> None:
        self._drive(q, self.servo.dt)

    def servo_stop(self) -> None:
        with self._lock:
            self._prev = self.q.copy()
            self.sim.data.ctrl[:6] = self.q
            self.sim.data.ctrl[6:12] = 0.0
            self.qd = np.zeros(6)
            self.stop_times.append(time.time())
        self.end_motion()

    def tcp_mm(self) -> np.ndarray:
        with self._lock:  # the servo thread steps the same MjData
            self._mj.mj_kinematics(self.sim.model, self.sim.data)
            return np.asarray(self.sim.tcp_mm())


def mujoco_twin(servo: ServoConfig, q0: np.ndarray | None = None,
                tool_T: np.ndarray | None = None, cell_file: str | None = None,
                clock: SimClock | None = None) -> MujocoTwin:
    """The MuJoCo backend (the cell file sets the model; None = the bundled cell)."""
    return MujocoTwin(servo, q0=q0, tool_T=tool_T, cell_file=cell_file, clock=clock)
