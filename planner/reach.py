"""Reachability of a batch of tool poses: inverse kinematics on the home branch and its limits.

``Reach`` solves the UR5e's IK on the branch of the home pose and checks each pose against the
joint limits (with the cell's margin), the shoulder/wrist singularities and the cell's clearance;
``Evaluation`` holds the verdict per pose, a ``PoseStatus`` (``OK``, or the code of one of
``REASONS``). Every planner stage that places the nozzle (orientation, placement, entry,
preflight) checks poses here.
Positions are mm (metres only at the kinematics' boundary), angles rad.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from planner import kinematics as kin
from planner.cell import CellConfig
from planner.collision import CollisionModel


class PoseStatus(IntEnum):
    """Why a tool pose is not reachable within the limits (``OK``: it is); stored as int8 per
    pose (``Evaluation.status``, ``Orientation.status``). ``REASONS`` says what each means."""

    OK = 0
    NO_IK = 1
    JOINT_LIMIT = 2
    SINGULAR = 3
    COLLISION = 4
    ALPHA = 5


OK, NO_IK, JOINT_LIMIT, SINGULAR, COLLISION, ALPHA = PoseStatus  # the members by name
REASONS: dict[int, str] = {
    NO_IK: "out of reach (no inverse kinematics solution on the home branch)",
    JOINT_LIMIT: "joint limit",
    SINGULAR: "near a singularity",
    COLLISION: "collision",
    ALPHA: "printing angle alpha outside the allowed range",
}


@dataclass(frozen=True)
class Evaluation:
    """A batch of tool poses checked for reachability.

    Attributes:
        q: (S, 6) float64, rad, joint solution on the home branch (nearest to ``q_ref``);
            nan where no solution.
        status: (S,) int8, a ``PoseStatus``: OK or NO_IK, JOINT_LIMIT, SINGULAR, COLLISION.
        singular: (S,) float64, distance from the singularities (``singularity_margin``).
        clearance: (S,) float64, mm (nan if not computed or no solution).
        margin: (S,) float64, rad, smallest distance to a joint position limit.
        pair: (S,) int32, index of the closest collision pair (into CollisionModel.names).
    """

    q: np.ndarray
    status: np.ndarray
    singular: np.ndarray
    clearance: np.ndarray
    margin: np.ndarray
    pair: np.ndarray


class Reach:
    """Checks tool poses of one cell: IK branch of home, limits, singularity, clearance."""

    def __init__(self, cell: CellConfig, collision: CollisionModel | None = None) -> None:
        self.cell = cell
        self.collision = collision if collision is not None else CollisionModel(cell)
        self.home = np.radians(cell.robot.home_deg)
        self.branch = int(kin.branch_of(self.home))
        margin = np.radians(cell.planning.joint_margin_deg)
        self.lo = np.radians(cell.robot.joint_min_deg)
        self.hi = np.radians(cell.robot.joint_max_deg)
        self.lo_safe = self.lo + margin
        self.hi_safe = self.hi - margin
        self.tool_m = cell.tool.tool_T.copy()
        self.tool_m[:3, 3] /= 1000.0
        self.tool_inv_m = np.linalg.inv(self.tool_m)

    def solve(self, tcp_mm: np.ndarray, R: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
        """IK on the home branch, each angle wrapped to the turn nearest ``q_ref`` (6,) or (S, 6).

        Args:
            tcp_mm: (S, 3) float64, mm, nozzle tip in the base frame.
            R: (S, 3, 3) float64, tool orientations in the base frame.
        Returns:
            (S, 6) float64, rad; nan rows where there is no solution.
        """
        q = np.empty((len(tcp_mm), 6))
        chunk = 16384  # cache-sized batches: large temporaries dominate otherwise
        for start in range(0, len(tcp_mm), chunk):
            sl = slice(start, start + chunk)
            T = np.zeros((len(tcp_mm[sl]), 4, 4))
            T[:, :3, :3] = R[sl]
            T[:, :3, 3] = tcp_mm[sl] / 1000.0
            T[:, 3, 3] = 1.0
            q[sl] = kin.ik(T @ self.tool_inv_m, (self.branch,))[0][:, 0]
        return self.wrap(q, q_ref)

    def wrap(self, q: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
        """Each angle of ``q`` (S, 6) shifted by whole turns to lie within the joint limits,
        nearest ``q_ref`` (6,) or (S, 6); the nearest turn if no shift fits."""
        near = q + 2 * np.pi * np.round((q_ref - q) / (2 * np.pi))
        cand = near[..., None] + 2 * np.pi * np.array([0.0, -1.0, 1.0])  # (S, 6, 3)
        inside = (cand >= self.lo[:, None]) & (cand <= self.hi[:, None])
        dist = np.abs(cand - np.broadcast_to(q_ref, q.shape)[..., None])
        dist = np.where(inside, dist, dist + 1e6)
        pick = np.argmin(dist, axis=-1)
        return np.take_along_axis(cand, pick[..., None], axis=-1)[..., 0]

    def check(
        self, q: np.ndarray, clearance: bool = True, iters: int = 14
    ) -> Evaluation:
        """Status and margins of configurations ``q`` (S, 6) rad (nan rows = no IK)."""
        S = len(q)
        status = np.zeros(S, dtype=np.int8)
        has = ~np.isnan(q).any(axis=1)
        status[~has] = NO_IK
        qs = np.where(has[:, None], q, self.home)
        margin = np.minimum(qs - self.lo, self.hi - qs).min(axis=1)
        limit = np.any((qs < self.lo_safe) | (qs > self.hi_safe), axis=1)
        status[has & limit] = JOINT_LIMIT
        singular = kin.singularity_margin(qs)
        sing = singular < self.cell.planning.singular_margin
        status[has & ~limit & sing] = SINGULAR
        clear = np.full(S, np.nan)
        pair = np.full(S, -1, dtype=np.int32)
        if clearance and has.any():
            c = self.collision.clearance(qs[has], iters=iters)
            clear[has] = c.distance
            pair[has] = c.pair
            hit = has & (clear < self.cell.planning.clearance_mm)
            status[hit & (status == OK)] = COLLISION
        return Evaluation(q, status, singular, clear, margin, pair)

    def cost(self, ev: Evaluation) -> np.ndarray:
        """Margin cost (S,) of evaluated poses: inf if not OK, small with wide margins."""
        c_clear = np.maximum(0.0, 1.0 - np.nan_to_num(ev.clearance, nan=1e3) / 50.0) ** 2
        c_sing = np.maximum(0.0, 1.0 - ev.singular / 0.3) ** 2
        c_joint = np.maximum(0.0, 1.0 - ev.margin / np.radians(30.0)) ** 2
        cost = c_clear + c_sing + c_joint
        return np.where(ev.status == OK, cost, np.inf)
