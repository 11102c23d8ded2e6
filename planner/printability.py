"""What ``mesp plan`` will refuse whatever the placement, said when the job is sliced.

The planner first sets the printing directions it follows (``directions``: the slicer's
repair of single-waypoint spikes, then the bounded smoothing along each path). Its bend test
(``refusal.bends``: waypoints where no nozzle axis the cell allows keeps alpha within range on
both the arriving and the leaving step; downward printing directions among them) needs only
those directions, the paths and the cell's alpha range, tilt and lean, not a pose: on a whole
toolpath it takes well under a second. ``check`` runs it at slicing time, so ``mesp slice``
says which waypoints the planner will refuse in any placement, with the refusal's own
one-line reason and fix, before anyone plans.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from core.stages import Toolpath
from planner.cell import CellConfig
from planner.path_smoothing import smooth_along_paths
from planner.placement import bend_refusal
from planner.refusal import bends
from slicer.normals import repair_normals


class Directions(NamedTuple):
    """The printing directions the planner follows.

    Attributes:
        toolpath: the toolpath with its normals repaired and smoothed.
        repaired: (N,) bool, waypoints whose normal was a spike and was replaced.
        smoothed: (N,) float64, rad, how far each normal was turned by the smoothing.
    """

    toolpath: Toolpath
    repaired: np.ndarray
    smoothed: np.ndarray


def directions(toolpath: Toolpath, cell: CellConfig) -> Directions:
    """The toolpath with the printing directions the planner follows (module docstring)."""
    toolpath, repaired = repair_normals(toolpath)
    toolpath, smoothed = smooth_along_paths(toolpath, cell.planning.smooth_length_mm,
                                            cell.planning.smooth_max_deg)
    return Directions(toolpath, repaired, smoothed)


def check(toolpath: Toolpath, cell: CellConfig) -> tuple[dict[str, Any], str | None]:
    """The bend test on the planner's printing directions: the report section
    ``printability`` and, where waypoints would be refused, one line saying so with the
    refusal's cause and fix (None where none would)."""
    planned = directions(toolpath, cell).toolpath
    found = bends(planned, cell)
    pl = cell.planning
    section: dict[str, Any] = {"alpha_range_deg": [pl.alpha_min_deg, pl.alpha_max_deg],
                               "lean_max_deg": pl.lean_max_deg,
                               "refused_waypoints": len(found.waypoint)}
    if not len(found.waypoint):
        return section, None
    refusal = bend_refusal(planned, cell, found)
    i = int(found.waypoint[0])
    note = f"{refusal.problem}: `mesp plan` will refuse the job; fix: {refusal.fix}"
    section.update(first_waypoint=i, first_layer=int(planned.layer[i]),
                   layers=np.unique(planned.layer[found.waypoint])[:10].tolist(),
                   cause=str(refusal.cause), note=note)
    return section, note
