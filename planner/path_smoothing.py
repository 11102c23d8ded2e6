"""Printing directions smoothed along each path by arc length, within a bounded deviation.

Why: the nozzle follows the layer normal, and the tool is long (the tip 460 mm from the
flange on the bundled cell), so every kink of the normal between two waypoints is a jump of
the flange's velocity by 460 mm times the jump of the normal's turn rate. The layer normals
come from the faceted layer surfaces and kink at nearly every waypoint (a few deg/mm on real
scans): the joint accelerations then bound the TCP speed at the kinks, and the time law slows
the nozzle below the toolpath's speed. Smoothing over a fixed number of waypoints (what the
planner did before) depends on their spacing; the kinks are a matter of millimetres.

How: per path, the normals are diffused along the arc length s, the implicit heat step
(M + t L) n = M n0 with L the path's graph Laplacian (edge weights 1 / segment length), M the
length each waypoint stands for and t = sigma^2 / (2 STEPS), taken STEPS times (one step's
kernel is exponential, with long tails; a few make it close to a Gaussian of width sigma), so
a kink is spread over about +-sigma mm whatever the spacing. Paths are not coupled (a move
between two paths does not carry the printing direction over); all paths are one tridiagonal
system. Only near waypoints where the normal turns faster than TURN_DEG_PER_MM (fading out
over about 2 sigma): a layer curving steadily keeps its exact normals. Each result is turned
back towards its own normal so it deviates at most ``max_deg`` from it: alpha changes by at
most that much, and the orientation stage and the verification check alpha against the
result as against any printing direction.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.linalg import solve_banded

from core.stages import Toolpath
from planner.nozzle_axis import unit
from planner.upright import turn_towards

MIN_SEGMENT_MM = 1e-3  # repeated waypoints count as this far apart (no infinite coupling)
STEPS = 4  # implicit diffusion steps
TURN_DEG_PER_MM = 1.5  # normals turning faster than this between waypoints are smoothed
FADE = 0.05  # the diffused indicator of fast turns (1 mm per waypoint) below which the
# smoothing fades out


def smooth_along_paths(toolpath: Toolpath, sigma_mm: float, max_deg: float
                       ) -> tuple[Toolpath, np.ndarray]:
    """The toolpath with its normals smoothed along each path (module docstring).

    Args:
        toolpath: its ``normal`` (N, 3) unit, ``position`` (N, 3) mm and ``path`` (N,) are read.
        sigma_mm: float, mm, the smoothing length (about the standard deviation of a Gaussian
            in arc length); 0 leaves the normals as they are.
        max_deg: float, deg, the largest turn of a normal.

    Returns:
        The toolpath with the smoothed normals, and the (N,) float64 turn of each, rad.
    """
    n = np.asarray(toolpath.normal, dtype=np.float64)
    N = len(n)
    if N < 3 or sigma_mm <= 0 or max_deg <= 0:
        return toolpath, np.zeros(N)
    path = np.asarray(toolpath.path)
    same = path[1:] == path[:-1]
    length = np.maximum(np.linalg.norm(np.diff(toolpath.position, axis=0), axis=1),
                        MIN_SEGMENT_MM)
    coupled = np.where(same, 1.0 / length, 0.0)  # (N - 1,) Laplacian edge weights
    inside = np.where(same, length, 0.0)
    # each waypoint stands for half of each segment of its path it touches; a lone
    # waypoint (a path of one) for MIN_SEGMENT_MM, which keeps the system regular
    mass = np.maximum(0.5 * (np.r_[inside, 0.0] + np.r_[0.0, inside]), MIN_SEGMENT_MM)
    t = 0.5 * sigma_mm**2 / STEPS
    bands = np.zeros((3, N))
    bands[0, 1:] = -t * coupled  # upper diagonal
    bands[1] = mass + t * (np.r_[coupled, 0.0] + np.r_[0.0, coupled])
    bands[2, :-1] = -t * coupled  # lower diagonal

    def diffuse(values: np.ndarray) -> np.ndarray:
        for _ in range(STEPS):  # a few banded solves of all paths at once
            values = solve_banded((1, 1), bands, mass[:, None] * values)
        return values

    mean = unit(diffuse(n))
    bad = np.linalg.norm(mean, axis=1) < 0.5  # normals that cancel out: keep the original
    mean[bad] = n[bad]
    # only where the normal turns fast (a curved layer turning steadily keeps its normals:
    # the mean along a ring would lean them towards its axis), fading in over sigma
    turn_step = np.arccos(np.clip(np.einsum("ij,ij->i", n[1:], n[:-1]), -1.0, 1.0))
    fast_step = same & (turn_step > np.radians(TURN_DEG_PER_MM) * length)
    fast = np.r_[fast_step, False] | np.r_[False, fast_step]
    # each fast waypoint counts as 1 mm of path, whatever the spacing (a kink is a point)
    weight = np.clip(diffuse((fast / mass)[:, None])[:, 0] / FADE, 0.0, 1.0)
    gap = np.arccos(np.clip(np.einsum("ij,ij->i", mean, n), -1.0, 1.0))
    out = turn_towards(n, mean, np.minimum(weight * gap, np.radians(max_deg)))
    turn = np.arccos(np.clip(np.einsum("ij,ij->i", out, n), -1.0, 1.0))
    return replace(toolpath, normal=out), turn
