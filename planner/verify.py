"""The executed trajectory checked against every limit the plan claims, sample by sample.

The stages before decide poses on their own samples (alpha against the steps they know of,
clearance every few samples and densely near the requirement, joint rates from the time law).
What the robot executes is the trajectory: the joint path between its samples and their
times. This module recomputes from it alone (forward kinematics of ``q``, chords between the
tips, finite differences in time) what a plan promises and reports every breach, so a plan
is never "ok" while one sample breaks a limit:

* alpha: the nozzle axis at both ends of every depositing step against the step's chord
  (steps shorter than ``ALPHA_MIN_STEP_MM`` lay a dot and are exempt);
* clearance: the distance of arm and tool to the cell at every sample;
* joint range and joint speed (|dq| / dt of each step);
* TCP speed: no depositing step faster than the toolpath's speed (too little ink per mm).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from core.tolerance import tol
from planner import kinematics as kin
from planner.nozzle_axis import ALPHA_MIN_STEP_MM, alpha_of
from planner.reach import Reach
from planner.status import PlanStatus
from planner.trajectory import Trajectory

ANGLE_TOL_DEG = 1e-6  # numerical slack of the alpha check, deg
SPEED_TOL = 1e-3  # relative slack of the speed checks (time steps are floats)


@dataclass(frozen=True)
class Breach:
    """One limit broken on the executed trajectory.

    Attributes:
        status: which limit.
        count: samples (or steps) breaking it.
        sample: the first of them (trajectory index).
        waypoint: the toolpath waypoint at or before that sample (-1 before the toolpath).
        worst: the worst value found (deg, mm, or a ratio to the limit).
        limit: the limit it was checked against, same unit.
        detail: what was measured, for the message ("alpha 64.4 deg", "extruder vs gel").
    """

    status: PlanStatus
    count: int
    sample: int
    waypoint: int
    worst: float
    limit: float
    detail: str


@dataclass(frozen=True)
class Verification:
    """Every check's outcome on the executed trajectory.

    Attributes:
        breaches: the broken limits, in the order of ``PlanStatus`` (empty when all hold).
        alpha_deg: (min, max) alpha at both ends of the depositing steps (nan if none).
        min_clearance_mm: smallest clearance over every sample.
        joint_speed_fraction: largest |dq| / dt over the velocity limit, over all steps.
        tcp_speed_ratio: largest step speed over the toolpath speed on depositing steps.
        seconds: time the checks took, s.
    """

    breaches: tuple[Breach, ...]
    alpha_deg: tuple[float, float]
    min_clearance_mm: float
    joint_speed_fraction: float
    tcp_speed_ratio: float
    seconds: float

    @property
    def ok(self) -> bool:
        """No limit is broken."""
        return not self.breaches

    def as_report(self) -> dict[str, object]:
        """The ``plan.verified`` section of report.json."""
        return {
            "ok": self.ok,
            "alpha_deg": [round(a, 3) for a in self.alpha_deg],
            "min_clearance_mm": round(self.min_clearance_mm, 3),
            "joint_speed_fraction": round(self.joint_speed_fraction, 4),
            "tcp_speed_ratio": round(self.tcp_speed_ratio, 4),
            "breaches": [{"status": str(b.status), "count": b.count, "sample": b.sample,
                          "waypoint": b.waypoint, "worst": round(b.worst, 3),
                          "limit": round(b.limit, 3), "detail": b.detail}
                         for b in self.breaches],
            "seconds": round(self.seconds, 3),
        }


def _waypoint_before(waypoint: np.ndarray, i: int) -> int:
    """The toolpath waypoint at sample ``i`` or the last one before it (-1 if none)."""
    w = waypoint[: i + 1]
    w = w[w >= 0]
    return int(w[-1]) if len(w) else -1


def verify(traj: Trajectory, target_speed: np.ndarray, reach: Reach) -> Verification:
    """Check ``traj`` against the limits of ``reach.cell`` (see module docstring).

    Args:
        traj: the trajectory as it will be executed.
        target_speed: (M,) float64, mm/s, the speed asked for at each sample (the toolpath's
            on the toolpath, the move speed on entry and exit).
        reach: the pose checker of the cell the plan was made for (gel level included).
    """
    start = time.perf_counter()
    cell = reach.cell
    pl = cell.planning
    breaches: list[Breach] = []
    M = len(traj)
    wp = traj.waypoint

    def add(status: PlanStatus, bad: np.ndarray, worst: float, limit: float,
            detail: str) -> None:
        idx = np.flatnonzero(bad)
        if len(idx):
            i = int(idx[0])
            breaches.append(Breach(status, len(idx), i, _waypoint_before(wp, i), worst, limit,
                                   detail))

    # alpha at both ends of every depositing step, against the chord the tip travels
    axis = kin.fk(traj.q, reach.tool_m)[:, :3, 2]
    chord = np.diff(traj.tcp, axis=0)
    length = np.linalg.norm(chord, axis=1)
    dep = traj.extrude[:-1] & (length > ALPHA_MIN_STEP_MM)
    a0 = np.degrees(alpha_of(axis[:-1], chord))
    a1 = np.degrees(alpha_of(axis[1:], chord))
    lo, hi = pl.alpha_min_deg - ANGLE_TOL_DEG, pl.alpha_max_deg + ANGLE_TOL_DEG
    worst_end = np.where(np.abs(a0 - 90.0) >= np.abs(a1 - 90.0), a0, a1)
    off = dep & ((worst_end < lo) | (worst_end > hi))
    alpha_range = ((float(np.minimum(a0, a1)[dep].min()), float(np.maximum(a0, a1)[dep].max()))
                   if dep.any() else (float("nan"), float("nan")))
    if off.any():
        far = worst_end[off][np.argmax(np.abs(worst_end[off] - 90.0))]
        limit = pl.alpha_min_deg if far < 90.0 else pl.alpha_max_deg
        add(PlanStatus.ALPHA, off, float(far), limit, f"alpha {far:.1f} deg")

    # clearance at every sample
    clear = reach.collision.clearance(traj.q)
    near = clear.distance < pl.clearance_mm - tol.slack
    k = int(np.argmin(clear.distance)) if M else -1
    min_clear = float(clear.distance[k]) if M else float("inf")
    if near.any():
        add(PlanStatus.CLEARANCE, near, min_clear, pl.clearance_mm,
            f"{min_clear:.2f} mm, {reach.collision.names[int(clear.pair[k])]}")

    # joint range and joint speed as executed (linear in joint space between samples)
    outside = np.any((traj.q < reach.lo) | (traj.q > reach.hi), axis=1)
    if outside.any():
        add(PlanStatus.JOINT_RANGE, outside, float(np.degrees(np.max(np.maximum(
            reach.lo - traj.q, traj.q - reach.hi)))), 0.0, "deg beyond the limit")
    dt = np.diff(traj.t)
    vmax = np.radians(cell.robot.max_velocity_deg_s)
    frac = (np.abs(np.diff(traj.q, axis=0)) / np.maximum(dt, tol.zero)[:, None] / vmax).max(
        axis=1) if M > 1 else np.zeros(0)
    joint_frac = float(frac.max()) if len(frac) else 0.0
    fast = frac > 1.0 + SPEED_TOL
    if fast.any():
        add(PlanStatus.JOINT_SPEED, np.r_[fast, False], joint_frac, 1.0,
            f"{joint_frac:.2f} x the velocity limit")

    # TCP speed on depositing steps: never faster than asked (target varies linearly)
    v = length / np.maximum(dt, tol.zero) if M > 1 else np.zeros(0)
    target = 0.5 * (target_speed[:-1] + target_speed[1:])
    moving = traj.extrude[:-1] & (length > tol.still)
    ratio = np.where(moving, v / np.maximum(target, tol.zero), 0.0)
    tcp_ratio = float(ratio.max()) if len(ratio) else 0.0
    over = ratio > 1.0 + SPEED_TOL
    if over.any():
        add(PlanStatus.TCP_SPEED, np.r_[over, False], tcp_ratio, 1.0,
            f"{tcp_ratio:.2f} x the toolpath speed")
    return Verification(tuple(breaches), alpha_range, min_clear, joint_frac, tcp_ratio,
                        time.perf_counter() - start)
