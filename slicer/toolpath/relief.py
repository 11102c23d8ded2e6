"""Steps that leave their layer: bends of a path out of the layer's tangent plane, relieved.

A path follows its layer surface, whose triangles come from marching tetrahedra on the tet
mesh. Where a thin layer curls (the membrane's dome edge at 0.70 mm layers: neighbouring
facets 30 deg apart), a stripe crossing the facets can zig-zag up and down its layer: a step
rises 50 deg against the waypoint's printing direction while the one before runs flat. The
nozzle prints along -normal within the cell's alpha range (paper section 3.1: [70, 110] deg,
i.e. a step within 20 deg of the layer's tangent plane); at such a bend no nozzle axis is
within range of both steps, and the planner refuses the waypoint (2 of 5 fresh tet meshes of
the membrane at 0.70 mm, session 14).

``relieve_bends`` moves such a waypoint along its printing direction towards the chord of its
two neighbours (the point that splits the chord in the ratio of the two step lengths), by at
most ``cap`` x its layer height H in all, and repeats on what is left. Of neighbouring
offenders only the sharpest bend (the largest change of elevation from the arriving to the
leaving step) moves in one round: a single raised waypoint makes its neighbours' steps steep
too, and lowering it alone mends all three. A few waypoints per job, a few tenths of a
millimetre, inside the slab the filament fills anyway. Widths, speeds and normals stay; the
ink of the moved segments changes with their length (reported, ~1e-6 of the job).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.alpha_range import AlphaRange
from core.stages import Toolpath
from core.tolerance import tol

MIN_STEP_MM = 0.05  # shorter steps have no direction worth checking
ITERATIONS = 6


@dataclass(frozen=True)
class BendRelief:
    """What ``relieve_bends`` did.

    Attributes:
        moved: (k,) int64, indices of the waypoints moved.
        offset_mm: (k,) float64, mm, how far each moved along its printing direction.
        left: int, steps still beyond the limit (where the cap stopped a move).
        ink_change: float, relative change of the job's ink (segment length / speed).
    """

    moved: NDArray[np.int64]
    offset_mm: NDArray[np.float64]
    left: int
    ink_change: float

    def as_dict(self) -> dict[str, Any]:
        """report.json's ``toolpath.bend_relief``."""
        return {"waypoints": len(self.moved),
                "max_offset_mm": float(np.abs(self.offset_mm).max()) if len(self.moved) else 0.0,
                "steps_left_beyond_limit": self.left, "ink_change": self.ink_change}


def step_elevation(toolpath: Toolpath, position: NDArray[np.float64] | None = None,
                   among: NDArray[np.int64] | None = None
                   ) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64],
                              NDArray[np.float64], NDArray[np.float64]]:
    """The interior waypoints i of depositing runs (i - 1, i, i + 1 one path, all extruding,
    both steps at least MIN_STEP_MM; only those in ``among`` if given) and, for each, the
    elevation (rad) of the arriving and the leaving step above the plane normal to its
    printing direction, and their lengths (mm): (i, elevation_in, elevation_out, length_in,
    length_out)."""
    p = toolpath.position if position is None else position
    n, path, on = toolpath.normal, toolpath.path, toolpath.extrude
    if len(p) < 3:
        empty = np.zeros(0)
        return np.zeros(0, np.int64), empty, empty, empty, empty
    i = np.arange(1, len(p) - 1) if among is None else among[(among >= 1) & (among < len(p) - 1)]
    ok = (path[i - 1] == path[i]) & (path[i + 1] == path[i]) & on[i - 1] & on[i] & on[i + 1]
    d_in, d_out = p[i] - p[i - 1], p[i + 1] - p[i]
    l_in, l_out = np.linalg.norm(d_in, axis=1), np.linalg.norm(d_out, axis=1)
    ok &= (l_in > MIN_STEP_MM) & (l_out > MIN_STEP_MM)
    i, d_in, d_out, l_in, l_out = i[ok], d_in[ok], d_out[ok], l_in[ok], l_out[ok]
    up_in = np.einsum("ij,ij->i", d_in, n[i]) / l_in
    up_out = np.einsum("ij,ij->i", d_out, n[i]) / l_out
    return (i.astype(np.int64), np.arcsin(np.clip(up_in, -1.0, 1.0)),
            np.arcsin(np.clip(up_out, -1.0, 1.0)), l_in, l_out)


def relieve_bends(toolpath: Toolpath, alpha: AlphaRange | None = None, cap: float = 0.5
                  ) -> tuple[Toolpath, BendRelief]:
    """``toolpath`` with the waypoints whose arriving or leaving step rises or falls more
    than the cell's ``alpha.step_elevation_deg`` (None: the bundled cell's range) against the
    waypoint's printing direction moved towards their neighbours' chord (module doc), each by
    at most ``cap`` x its H in all."""
    limit = np.radians((alpha or AlphaRange.bundled()).step_elevation_deg)
    p = np.array(toolpath.position, dtype=np.float64)
    n = toolpath.normal
    total = np.zeros(len(p))
    budget = cap * np.asarray(toolpath.height, dtype=np.float64)
    i, e_in, e_out, _, _ = step_elevation(toolpath, p)
    # after the first look only the offenders and their neighbours can change
    around = np.unique(np.clip(i[(np.abs(e_in) > limit) | (np.abs(e_out) > limit)][:, None]
                               + np.arange(-2, 3), 0, max(len(p) - 1, 0)))
    for _ in range(ITERATIONS):  # a handful of waypoints: a move can tip a neighbour's step
        i, e_in, e_out, l_in, l_out = step_elevation(toolpath, p, around)
        bad = (np.abs(e_in) > limit) | (np.abs(e_out) > limit)
        # of neighbouring offenders, the sharpest bend first
        bend = np.zeros(len(p) + 1)  # index -1 and len(p) read as 0
        bend[i[bad]] = np.abs(e_out - e_in)[bad]
        sharpest = (bend[i] >= bend[i - 1]) & (bend[i] >= bend[i + 1])
        pick = bad & sharpest
        i, l_in, l_out = i[pick], l_in[pick], l_out[pick]
        if not len(i):
            break
        w = (l_in / (l_in + l_out))[:, None]
        target = p[i - 1] + w * (p[i + 1] - p[i - 1])
        want = np.einsum("ij,ij->i", target - p[i], n[i])
        room = budget[i] - np.abs(total[i])
        step = np.clip(want, -room, room)  # |total + step| <= budget
        if not np.any(np.abs(step) > tol.zero):
            break
        p[i] += step[:, None] * n[i]
        total[i] += step
    i, e_in, e_out, _, _ = step_elevation(toolpath, p, around)
    left = int(np.sum((np.abs(e_in) > limit) | (np.abs(e_out) > limit)))
    moved = np.flatnonzero(np.abs(total) > tol.zero).astype(np.int64)
    if not len(moved):
        return toolpath, BendRelief(moved, np.zeros(0), left, 0.0)
    out = replace(toolpath, position=p)
    # the ink changes only on the segments next to a moved waypoint
    seg = np.unique(np.clip(np.concatenate([moved - 1, moved]), 0, max(len(p) - 2, 0)))
    change = _ink(out, seg) - _ink(toolpath, seg)
    return out, BendRelief(moved, total[moved], left, change / max(_ink(toolpath), tol.zero))


def _ink(toolpath: Toolpath, segments: NDArray[np.int64] | None = None) -> float:
    """Sum over the depositing segments k -> k + 1 (all, or ``segments``) of length / mean
    speed (ink / C, s)."""
    k = np.arange(max(len(toolpath) - 1, 0)) if segments is None else segments
    p, v, path, on = toolpath.position, toolpath.speed, toolpath.path, toolpath.extrude
    dep = (path[k + 1] == path[k]) & on[k + 1] & on[k]
    length = np.linalg.norm(p[k + 1] - p[k], axis=1)
    mean_v = np.maximum(0.5 * (v[k + 1] + v[k]), tol.zero)
    return float(np.sum(np.where(dep, length / mean_v, 0.0)))
