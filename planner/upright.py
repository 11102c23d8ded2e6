"""Turn the nozzle towards vertical where following the layer normal would bring the arm
near a singularity.

Why: the tool is long (tip 460 mm from the flange on the bundled cell), so the wrist sits
~560 mm up the nozzle axis from the tip. Where a curved layer's printing direction leans
~40 deg towards the robot (the far side of the socket's rounded bottom), the wrist comes
within ~150 mm of the base axis: the UR shoulder singularity. There a 1 mm step turns the
shoulder and wrists by tens of degrees, the continuity stage must insert dozens of samples
per step, and the arm folds wrist 1 onto the shoulder between samples. Nothing at the sample
itself fails, so ``orientation.choose`` (which moves the axis only where a sample fails)
cannot see it.

How: per sample, the singularity margin (``kinematics.singularity_margin``) of the pose with
the nozzle on ``-normal``. Where it is below ``COMFORT``, the printing direction is turned
towards the cell's up axis by the smallest of 5, 10, ... ``upright_max_deg`` that restores
the margin (never past vertical; for an extruding sample only as far as alpha stays within
its range), or the best of them if none does. The angles are ramped in and out at 1 deg per
sample, so the wrist moves smoothly, and ``choose`` then works on the turned directions
(its tilts and leans are relative to them). With the nozzle upright the wrist sits above the
tip, inside the tank's footprint, away from the base axis; the extruder body also rises out
of the gel.

The margin is computed at spin 0. It does not depend on the spin for a tool whose tip lies on
the flange axis (the bundled tool); for an offset tool it is an estimate, and the full checks
of ``choose`` decide.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from core.tolerance import tol
from planner import kinematics as kin
from planner.nozzle_axis import alpha_within, tool_rotation, unit
from planner.orientation import ramp
from planner.reach import Reach

COMFORT = 0.2  # singularity margin (0 singular, ~1 far) below which the nozzle is uprighted
STEP_DEG = 5.0  # candidate upright angles: STEP_DEG, 2 STEP_DEG, ... upright_max_deg


class Upright(NamedTuple):
    """Printing directions turned towards vertical where the arm needs it.

    Attributes:
        normal: (M, 3) float64, unit printing directions in the base frame, turned.
        angle: (M,) float64, rad, how far each was turned (0 where the margin is fine).
        margin: (M,) float64, singularity margin on the layer's ``-normal`` (0 without IK).
    """

    normal: np.ndarray
    angle: np.ndarray
    margin: np.ndarray


def turn_towards(normal: np.ndarray, target: np.ndarray, angle: np.ndarray | float
                 ) -> np.ndarray:
    """Unit directions ``normal`` (M, 3) turned towards the unit vectors ``target`` ((3,) or
    (M, 3)) by ``angle`` ((M,) or scalar) rad along the great circle, stopping at the target
    (a target opposite to or on the normal leaves it)."""
    target = np.broadcast_to(target, normal.shape)
    theta = np.arccos(np.clip(np.einsum("ij,ij->i", normal, target), -1.0, 1.0))
    a = np.minimum(angle, theta)
    s = np.sin(theta)
    ok = s > tol.slack
    w0 = np.where(ok, np.sin(theta - a) / np.where(ok, s, 1.0), 1.0)
    w1 = np.where(ok, np.sin(a) / np.where(ok, s, 1.0), 0.0)
    return unit(w0[:, None] * normal + w1[:, None] * target)


def _margin(reach: Reach, tcp: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Singularity margin (M,) of the poses with the nozzle on ``-normal`` at spin 0."""
    R = tool_rotation(-normal, np.zeros(len(normal)))
    q = reach.solve(tcp, R, reach.home)
    return np.nan_to_num(kin.singularity_margin(q), nan=0.0)


def upright(reach: Reach, tcp: np.ndarray, normal: np.ndarray, tangent: np.ndarray,
            extrude: np.ndarray, arrive: np.ndarray | None = None) -> Upright:
    """Printing directions turned towards vertical where the margin is thin (module docstring).

    Args:
        tcp: (M, 3) float64, mm, nozzle tip targets in the base frame.
        normal: (M, 3) float64, unit printing directions in the base frame.
        tangent: (M, 3) float64, unit motion directions in the base frame.
        extrude: (M,) bool; alpha limits apply to extruding samples only.
        arrive: (M, 3) float64, unit direction of the depositing step arriving at each sample,
            zero rows where it does not deposit (alpha holds against it too), or None.
    """
    cell = reach.cell
    M = len(tcp)
    up = unit(np.linalg.inv(cell.robot.base_T)[:3, :3] @ np.array([0.0, 0.0, 1.0]))
    margin = _margin(reach, tcp, normal)
    angle = np.zeros(M)
    low = np.flatnonzero(margin < COMFORT)
    n_steps = int(np.floor(cell.planning.upright_max_deg / STEP_DEG + tol.slack))
    if len(low) and n_steps:
        best = margin[low].copy()
        best_angle = np.zeros(len(low))
        done = np.zeros(len(low), dtype=bool)
        for k in range(1, n_steps + 1):  # a few candidate angles, each over all low samples
            rows = np.flatnonzero(~done)
            if not len(rows):
                break
            idx = low[rows]
            a = np.full(len(idx), np.radians(k * STEP_DEG))
            n2 = turn_towards(normal[idx], up, a)
            m2 = _margin(reach, tcp[idx], n2)
            allowed = alpha_within(cell, -n2, tangent[idx], extrude[idx],
                                   None if arrive is None else arrive[idx])
            better = allowed & (m2 > best[rows])
            best[rows[better]] = m2[better]
            best_angle[rows[better]] = a[better]
            done[rows[better & (m2 >= COMFORT)]] = True
        angle[low] = best_angle
        angle = ramp(angle, np.radians(1.0))
    return Upright(turn_towards(normal, up, angle), angle, margin)
