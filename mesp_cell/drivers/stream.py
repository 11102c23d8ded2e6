"""Trajectory streaming at the servo rate: resampling, pre-motion checks, the servo loop.

``StreamPlan.load`` reads ``trajectory.npz`` (by path and sha256), refuses a bad one with a
one-line reason before anything moves, and streams it at the servo period (each servo sample
interpolated when it is sent). ``ServoStream``
sends one servoJ per period inside initPeriod/waitPeriod, asks a guard before every sample
(the robot node's interlocks: extruder alive and running, e-stop, supervisor present), reports
every deposition waypoint it passes, and ends with servoStop.
"""

from __future__ import annotations

import hashlib
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from core.artifacts import load_npz
from core.errors import InputError
from core.tolerance import tol
from mesp_cell.drivers.robot_base import UR5E_Q_LIMIT, UR5E_QD_LIMIT, RobotDriver

MAX_PERIODS = 1 << 20  # servo periods a stream keeps for its jitter statistics (~35 min at 500 Hz)
SWING_LIMIT_MM = 0.5  # a depositing step may bow off the straight step by this much at most
TRAJECTORY_SCHEMA = {
    "t": (1, "f", None), "q": (2, "f", (6,)), "qd": (2, "f", (6,)), "tcp": (2, "f", (3,)),
    "waypoint": (1, "iu", None), "alpha": (1, "f", None), "extrude": (1, "b", None),
    "base_T": (2, "f", (4,)), "tool_T": (2, "f", (4,)), "model_T": (2, "f", (4,)),
}


def sha256_of(path: Path) -> str:
    """Hex sha256 of a file (artifacts travel by path + digest)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


class _ServoView:
    """Per-servo-sample values of a ``StreamPlan``, computed when indexed (an int, a slice or
    an int array, like an array of ``shape``); ``np.asarray`` builds them all (small plans
    and tests only)."""

    def __init__(self, plan: StreamPlan) -> None:
        self._plan = plan

    def __len__(self) -> int:
        return self._plan.samples

    def __getitem__(self, key: int | slice | np.ndarray) -> np.ndarray:
        return self._at(_indices(key, self._plan.samples))

    def _at(self, k: np.ndarray) -> np.ndarray:
        raise NotImplementedError  # each view says what a sample holds

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        out = self[:]
        return out if dtype is None else out.astype(dtype)


class ServoJoints(_ServoView):
    """Joint targets, rad, at the servo samples: (K, 6) float64, interpolated linearly."""

    @property
    def shape(self) -> tuple[int, int]:
        return (self._plan.samples, 6)

    def _at(self, k: np.ndarray) -> np.ndarray:
        t, q = self._plan.t, self._plan.q_knots
        tk = self._plan.dt * k
        i = np.clip(np.searchsorted(t, tk, side="right") - 1, 0, len(t) - 2)
        w = np.clip((tk - t[i]) / (t[i + 1] - t[i]), 0.0, 1.0)
        return q[i] + np.asarray(w)[..., None] * (q[i + 1] - q[i])


class ServoExtrude(_ServoView):
    """Deposition flags at the servo samples: (K,) bool; a sample deposits where the
    trajectory sample at or before it does."""

    @property
    def shape(self) -> tuple[int]:
        return (self._plan.samples,)

    def _at(self, k: np.ndarray) -> np.ndarray:
        t = self._plan.t
        src = np.clip(np.searchsorted(t, self._plan.dt * k, side="right") - 1, 0, len(t) - 1)
        return self._plan.extrude_knots[src]


def _indices(key: int | slice | np.ndarray, K: int) -> np.ndarray:
    """Servo sample indices (int64) for an int, slice or int array key into K samples."""
    if isinstance(key, slice):
        return np.arange(*key.indices(K), dtype=np.int64)
    k = np.asarray(key, dtype=np.int64)
    if np.any((k < -K) | (k >= K)):
        raise IndexError(f"servo sample index out of range for {K} samples")
    return np.where(k < 0, k + K, k)


@dataclass(frozen=True)
class StreamPlan:
    """A trajectory streamed at the servo period: servo sample k is the trajectory at
    t[0] + k dt, interpolated linearly in joint space when it is asked for (``q[k]``).

    Why on demand: a 30 h job (the socket) has 53 M servo samples; as arrays they took 2.5 GB
    of joint targets, 5.7 GB while building them and 16 s to load, in the robot node and the
    supervisor each.

    Attributes:
        dt: s, servo period.
        t: (M,) float64, s, trajectory sample times from the first (strictly increasing).
        q_knots: (M, 6) float64, rad, trajectory joint positions.
        extrude_knots: (M,) bool, deposition on the step after each trajectory sample.
        wp_id: (W,) int64, toolpath waypoint indices in the order they are reached.
        wp_sample: (W,) int64, servo sample at which each is reached (non-decreasing).
        wp_extrude: (W,) bool, the waypoint deposits material.
        wp_layer: (W,) int64, layer of each waypoint (-1 when toolpath.npz is absent).
        layers: number of layers (0 when unknown).
        tool_T: (4, 4) float64, mm, nozzle tip in the flange frame.
        flow_knots: (M,) float64, the extrusion rate over C on the step after each trajectory
            sample that keeps the toolpath's ink per millimetre where the arm is slower than
            the toolpath (``planner.flow.knot_flow_scale``); all 1 without toolpath.npz.
    """

    dt: float
    t: np.ndarray
    q_knots: np.ndarray
    extrude_knots: np.ndarray
    wp_id: np.ndarray
    wp_sample: np.ndarray
    wp_extrude: np.ndarray
    wp_layer: np.ndarray
    layers: int
    tool_T: np.ndarray
    flow_knots: np.ndarray

    @property
    def samples(self) -> int:
        """K: servo samples from the first trajectory sample to the last."""
        return int(np.floor(self.t[-1] / self.dt + tol.slack)) + 1

    @property
    def q(self) -> ServoJoints:
        """(K, 6) joint targets, rad, one per servo period (computed when indexed)."""
        return ServoJoints(self)

    @property
    def extrude(self) -> ServoExtrude:
        """(K,) deposition flags, one per servo period (computed when indexed)."""
        return ServoExtrude(self)

    def sample_of_waypoint(self, waypoint: int) -> int:
        """Servo sample at which ``waypoint`` is reached (0 for -1 = from the start)."""
        if waypoint < 0:
            return 0
        i = int(np.searchsorted(self.wp_id, waypoint))
        if i >= len(self.wp_id) or self.wp_id[i] != waypoint:
            raise InputError(f"waypoint {waypoint} is not in the trajectory", "check the job")
        return int(self.wp_sample[i])

    def q_at(self, k: int) -> np.ndarray:
        """(6,) joint targets, rad, of servo sample ``k`` (0 <= k < samples): the streaming
        loop's fast path."""
        t = self.t
        tk = self.dt * k
        i = min(max(int(np.searchsorted(t, tk, side="right")) - 1, 0), len(t) - 2)
        w = min(max((tk - t[i]) / (t[i + 1] - t[i]), 0.0), 1.0)
        return self.q_knots[i] + w * (self.q_knots[i + 1] - self.q_knots[i])

    def extrude_at(self, k: int) -> bool:
        """Whether servo sample ``k`` (0 <= k < samples) deposits."""
        i = int(np.searchsorted(self.t, self.dt * k, side="right")) - 1
        return bool(self.extrude_knots[min(max(i, 0), len(self.t) - 1)])

    def flow_at(self, k: int) -> float:
        """The extrusion rate over C for servo sample ``k`` (``flow_knots``)."""
        i = int(np.searchsorted(self.t, self.dt * k, side="right")) - 1
        return float(self.flow_knots[min(max(i, 0), len(self.t) - 1)])

    def first_extruding(self) -> int:
        """The first servo sample that deposits (``samples`` if none does)."""
        knots = np.flatnonzero(self.extrude_knots)
        if not len(knots):
            return self.samples
        # the first servo sample at or after each depositing trajectory sample
        k = np.ceil(self.t[knots] / self.dt - tol.slack).astype(np.int64)
        k = k[k < self.samples]
        if not len(k):
            return self.samples
        hit = np.flatnonzero(self.extrude[k])
        return int(k[hit[0]]) if len(hit) else self.samples

    @staticmethod
    def of_path(dt: float, t: np.ndarray, q: np.ndarray, tool_T: np.ndarray,
                hold_s: float = 0.0) -> StreamPlan:
        """A plan that moves along a timed joint path (``t``: (M,) s from 0, increasing;
        ``q``: (M, 6) rad) without depositing, then holds its end for ``hold_s``."""
        t = np.asarray(t, dtype=np.float64)
        q = np.asarray(q, dtype=np.float64)
        if hold_s > 0:
            t = np.append(t, t[-1] + hold_s)
            q = np.vstack([q, q[-1:]])
        empty = np.zeros(0, dtype=np.int64)
        return StreamPlan(dt, t - t[0], q, np.zeros(len(t), bool), empty, empty,
                          np.zeros(0, bool), empty, 0, np.asarray(tool_T, dtype=np.float64),
                          np.ones(len(t)))

    @staticmethod
    def load(path: Path, dt: float, sha256: str = "") -> StreamPlan:
        """Read, check and resample ``trajectory.npz``; any problem is a one-line InputError."""
        path = Path(path)
        if sha256 and path.is_file() and sha256_of(path) != sha256:
            raise InputError(f"{path} changed since it was planned (sha256 mismatch)",
                             "re-plan the job")
        a = load_npz(path, TRAJECTORY_SCHEMA)
        t, q = a["t"].astype(np.float64), a["q"].astype(np.float64)
        wp, ex = a["waypoint"].astype(np.int64), a["extrude"].astype(bool)
        M = t.shape[0]
        if M < 2 or any(a[n].shape[0] != M for n in ("q", "qd", "tcp", "waypoint", "extrude")):
            raise InputError(f"{path}: arrays need the same length >= 2", "re-plan the job")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q))):
            raise InputError(f"{path}: t or q holds NaN/inf", "re-plan the job")
        if np.any(np.diff(t) <= 0):
            i = int(np.argmax(np.diff(t) <= 0))
            raise InputError(f"{path}: time does not increase at sample {i + 1}", "re-plan the job")
        bad = np.abs(q) > UR5E_Q_LIMIT
        if bad.any():
            i, j = (int(v) for v in np.argwhere(bad)[0])
            raise InputError(f"{path}: joint {j + 1} at sample {i} is {np.degrees(q[i, j]):.0f}"
                             " deg, beyond the UR5e limit of +-360 deg", "re-plan the job")
        speed = np.abs(np.diff(q, axis=0)) / np.diff(t)[:, None]
        if np.any(speed > UR5E_QD_LIMIT * 1.05):
            i, j = (int(v) for v in np.argwhere(speed > UR5E_QD_LIMIT * 1.05)[0])
            raise InputError(f"{path}: joint {j + 1} needs {np.degrees(speed[i, j]):.0f} deg/s "
                             f"at sample {i}, above the UR5e limit of 180 deg/s",
                             "re-plan the job with a lower speed")
        # between samples the robot moves linearly in joint space: on a depositing step the
        # nozzle must stay on the path (a plan of an older version, or a hand-made file)
        from planner.continuity import pair_swing

        tool_m = np.asarray(a["tool_T"], dtype=np.float64).copy()
        tool_m[:3, 3] /= 1000.0
        dep = np.flatnonzero(ex[:-1] & ex[1:])
        off = pair_swing(q[dep], q[dep + 1], tool_m)
        if np.any(off > SWING_LIMIT_MM):
            i = int(dep[np.argmax(off > SWING_LIMIT_MM)])
            raise InputError(f"{path}: between samples {i} and {i + 1} the nozzle would leave "
                             f"the path by {off.max():.1f} mm (joint-space motion next to a "
                             "singularity)", "re-plan the job with this version of mesp plan")
        has = wp >= 0
        if np.any(np.diff(wp[has]) <= 0):
            raise InputError(f"{path}: waypoint indices are not increasing in time",
                             "re-plan the job")
        # servo sample k is at t0 + k dt (interpolated when streamed, see the class)
        t = t - t[0]
        K = int(np.floor(t[-1] / dt + tol.slack)) + 1
        wp_id = wp[has]
        wp_sample = np.minimum(np.ceil(t[has] / dt - tol.slack).astype(np.int64), K - 1)
        wp_layer = np.full(wp_id.shape, -1, dtype=np.int64)
        layers = 0
        flow = np.ones(M)
        tp = path.parent / "toolpath.npz"
        if tp.is_file():
            from types import SimpleNamespace

            from core.stages import Toolpath
            from planner.flow import knot_flow_scale

            toolpath = Toolpath.load(path.parent)
            if wp_id.size and wp_id.max() >= toolpath.layer.shape[0]:
                raise InputError(f"{path}: waypoint {int(wp_id.max())} is beyond the "
                                 f"{toolpath.layer.shape[0]} waypoints of toolpath.npz",
                                 "re-plan the job")
            wp_layer = toolpath.layer[wp_id].astype(np.int64)
            layers = int(toolpath.layer.max()) + 1 if toolpath.layer.size else 0
            if len(wp_id) == len(toolpath):  # a whole job's plan: the speeds it keeps
                flow = knot_flow_scale(toolpath, SimpleNamespace(t=t, waypoint=wp, extrude=ex))
        return StreamPlan(dt, t, q, ex, wp_id, wp_sample, ex[has], wp_layer, layers,
                          np.asarray(a["tool_T"], dtype=np.float64), flow)


@dataclass(frozen=True)
class StreamResult:
    """How a stream ended.

    Attributes:
        done: the last sample was sent. reason: why it stopped early ("" if done).
        last_sample: last sample sent (-1 if none). stop_t: time.time() of servoStop.
        periods: (n,) float64, s, measured servo periods, oldest first (for the jitter
            benchmark; the last MAX_PERIODS of a longer stream).
    """

    done: bool
    reason: str
    last_sample: int
    stop_t: float
    periods: np.ndarray


class ServoStream:
    """Streams ``plan`` from sample ``start`` on a driver, in the calling thread (``run``).

    Args:
        guard: called before each sample with its index; a non-empty string stops the stream
            with that reason before the sample is sent.
        on_sample: called after each sample is sent.
        on_waypoint: called (waypoint index in plan arrays) for each deposition waypoint passed.
        after_waypoint: waypoints up to this id were already deposited (resume) and are skipped.
    """

    def __init__(self, driver: RobotDriver, plan: StreamPlan, start: int = 0,
                 guard: Callable[[int], str] | None = None,
                 on_sample: Callable[[int], None] | None = None,
                 on_waypoint: Callable[[int], None] | None = None,
                 after_waypoint: int = -1) -> None:
        if not 0 <= start < plan.samples:
            raise InputError(f"start sample {start} outside the {plan.samples} samples",
                             "check the checkpoint")
        self.driver, self.plan, self.start = driver, plan, start
        self.guard = guard or (lambda k: "")
        self.on_sample = on_sample or (lambda k: None)
        self.on_waypoint = on_waypoint or (lambda i: None)
        self._next_wp = int(np.searchsorted(plan.wp_id, after_waypoint, side="right"))
        self._stop = threading.Event()
        self._reason = ""
        self.sample = start - 1

    def stop(self, reason: str) -> None:
        """Ask the loop to stop before its next sample (thread-safe; at most one period)."""
        if not self._stop.is_set():
            self._reason = reason
            self._stop.set()

    def run(self) -> StreamResult:
        """Stream until the end, a guard refusal, ``stop``, or a refused servoJ; then servoStop.

        With ``servo.realtime_priority`` the calling thread runs SCHED_FIFO while streaming
        (if the OS allows it; otherwise at normal priority).
        """
        prio = int(getattr(self.driver.servo, "realtime_priority", 0))
        raised = False
        if prio and hasattr(os, "sched_setscheduler"):
            try:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(prio))
                raised = True
            except OSError:  # not permitted: stream at normal priority
                pass
        try:
            return self._run()
        finally:
            if raised:
                os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))

    def _run(self) -> StreamResult:
        d, plan = self.driver, self.plan
        K = plan.samples
        # the last MAX_PERIODS servo periods (a ring: a 30 h stream has 53 M of them)
        periods = np.zeros(min(K - self.start, MAX_PERIODS))
        n, prev, reason = 0, 0.0, ""
        wp_sample, wp_extrude = plan.wp_sample, plan.wp_extrude
        overrun = float(getattr(d.servo, "overrun_s", 0.1))  # wall time, even on a fast twin
        for k in range(self.start, K):  # one iteration per servo period (500 Hz real time)
            t0 = d.init_period()
            if n:
                periods[(n - 1) % len(periods)] = t0 - prev
                if t0 - prev > overrun:
                    reason = f"servo loop stalled for {1000 * (t0 - prev):.0f} ms (watchdog)"
                    break
            prev = t0
            n += 1
            if self._stop.is_set():
                reason = self._reason
                break
            why = self.guard(k)
            if why:
                reason = why
                break
            if not d.servo_j(plan.q_at(k)):
                reason = ("protective stop" if d.protective_stopped()
                          else "servoJ refused: link to the controller lost")
                break
            self.sample = k
            while self._next_wp < len(wp_sample) and wp_sample[self._next_wp] <= k:
                if wp_extrude[self._next_wp]:
                    self.on_waypoint(self._next_wp)
                self._next_wp += 1
            self.on_sample(k)
            d.wait_period(t0)
        d.servo_stop()
        stop_t = time.time()
        done = not reason
        m = max(n - 1, 0)
        if m > len(periods):  # unroll the ring: oldest first
            periods = np.roll(periods, -(m % len(periods)))
        return StreamResult(done, reason, self.sample, stop_t, periods[: min(m, len(periods))])
