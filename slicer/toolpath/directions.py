"""Printing directions the robot must follow: how far from up, and how fast they turn.

The nozzle approaches along -normal, mounted on an arm above the tank: a printing direction
pointing downward (more than 90 deg from +z) cannot be printed by any cell, and one that
turns by more than ``JUMP_DEG`` between neighbouring waypoints of a path asks the wrist for
a swing no alpha in [70, 110] deg can absorb. ``direction_report`` counts both over the
extruding waypoints, so a slice that the planner will refuse for them says so at slicing
time, with the layers where they are.
"""

from __future__ import annotations

import numpy as np

from core.stages import Toolpath

DOWNWARD_DEG = 90.0  # a printing direction further than this from +z points downward
JUMP_DEG = 30.0  # turn of the printing direction between neighbouring waypoints of a path


def direction_report(tp: Toolpath) -> dict[str, object]:
    """report.json's ``toolpath.printing_direction``.

    Returns:
        {"max_from_up_deg", "p99_from_up_deg", "downward": extruding waypoints pointing
        downward, "downward_layers": up to 10 of their layers, "jumps": neighbouring
        extruding waypoints of one path whose directions differ by more than JUMP_DEG,
        "max_jump_deg", "jump_layers": up to 10 of their layers}.
    """
    normal = np.asarray(tp.normal, dtype=np.float64)
    ex = np.asarray(tp.extrude, dtype=bool)
    layer = np.asarray(tp.layer)
    if not ex.any():
        return {"max_from_up_deg": None, "p99_from_up_deg": None, "downward": 0,
                "downward_layers": [], "jumps": 0, "max_jump_deg": None, "jump_layers": []}
    up = np.degrees(np.arccos(np.clip(normal[:, 2], -1.0, 1.0)))
    down = ex & (up > DOWNWARD_DEG)
    same = (np.asarray(tp.path)[1:] == np.asarray(tp.path)[:-1]) & ex[1:] & ex[:-1]
    turn = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", normal[1:], normal[:-1]),
                                        -1.0, 1.0)))
    jump = same & (turn > JUMP_DEG)
    return {
        "max_from_up_deg": float(up[ex].max()),
        "p99_from_up_deg": float(np.percentile(up[ex], 99)),
        "downward": int(down.sum()),
        "downward_layers": np.unique(layer[down])[:10].tolist(),
        "jumps": int(jump.sum()),
        "max_jump_deg": float(turn[same].max()) if same.any() else 0.0,
        "jump_layers": np.unique(layer[1:][jump])[:10].tolist(),
    }
