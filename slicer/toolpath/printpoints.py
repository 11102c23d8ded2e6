"""The toolpath as compas_slicer printpoints JSON and as a CSV of waypoints.

compas_slicer's ``PrintOrganizer.output_printpoints_dict`` writes a flat mapping
``{"0": point, "1": point, ...}`` in print order; each point carries the fields of
``PrintPoint.to_data``: ``point``, ``layer_height``, ``mesh_normal``, ``up_vector``, ``frame``
(``{"point", "xaxis", "yaxis"}``), ``extruder_toggle``, ``velocity``, ``wait_time``,
``blend_radius``, ``closest_support_pt``, ``distance_to_support``, ``is_feasible``,
``attributes``. Here ``up_vector`` is the printing direction (our ``normal``, the layer growth
direction that compas_slicer's curved slicing also calls up), ``mesh_normal`` the in-layer
direction across the path (``path tangent x up``), so ``frame`` has x along the path and y
across it, as compas_slicer builds it (x = up x mesh_normal). Coordinates are the model frame,
mm; velocity mm/s. Our width, layer, path and pattern go into ``attributes``.
"""

from __future__ import annotations

import io
import json
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.stages import Toolpath
from core.tolerance import tol

PRINTPOINT_FIELDS = (
    "point", "layer_height", "mesh_normal", "up_vector", "frame", "extruder_toggle",
    "velocity", "wait_time", "blend_radius", "closest_support_pt", "distance_to_support",
    "is_feasible", "attributes",
)
CSV_COLUMNS = ("index", "layer", "path", "x_mm", "y_mm", "z_mm", "nx", "ny", "nz",
               "width_mm", "height_mm", "speed_mm_s", "extrude", "pattern")


def _unit(v: NDArray[np.float64], fallback: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rows of ``v`` (K, 3) normalised; rows shorter than 1e-12 replaced by ``fallback``."""
    n = np.linalg.norm(v, axis=1, keepdims=True)
    return np.where(n > tol.zero, v / np.maximum(n, tol.zero), fallback)


def tangents(toolpath: Toolpath) -> NDArray[np.float64]:
    """Unit direction of motion (N, 3) at each waypoint: towards the next one of its path.

    The last waypoint of a path takes the direction from its predecessor; a path of one
    waypoint takes any direction perpendicular to its normal.
    """
    p = toolpath.position
    n = len(p)
    fwd = np.zeros((n, 3))
    if n > 1:
        fwd[:-1] = p[1:] - p[:-1]
        same_next = np.r_[toolpath.path[1:] == toolpath.path[:-1], False]
        back = np.r_[np.zeros((1, 3)), p[1:] - p[:-1]]
        same_prev = np.r_[False, toolpath.path[1:] == toolpath.path[:-1]]
        fwd = np.where(same_next[:, None], fwd, np.where(same_prev[:, None], back, 0.0))
    # projected on the layer (perpendicular to the normal), the frame stays orthonormal
    up = toolpath.normal
    fwd = fwd - np.sum(fwd * up, axis=1, keepdims=True) * up
    any_perp = np.cross(up, np.where(np.abs(up[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
    return _unit(fwd, _unit(any_perp, np.array([1.0, 0.0, 0.0])))


def printpoints(toolpath: Toolpath) -> dict[str, dict[str, Any]]:
    """The compas_slicer printpoints mapping of every waypoint, in print order."""
    up = toolpath.normal
    x = tangents(toolpath)
    across = np.cross(x, up)  # mesh_normal: x = up x mesh_normal holds for this choice
    rows = zip(toolpath.position.tolist(), toolpath.height.tolist(), across.tolist(),
               up.tolist(), x.tolist(), toolpath.extrude.tolist(), toolpath.speed.tolist(),
               toolpath.width.tolist(), toolpath.layer.tolist(), toolpath.path.tolist(),
               toolpath.pattern.tolist(), strict=True)
    out: dict[str, dict[str, Any]] = {}
    for i, (p, h, mn, u, xa, on, v, w, lay, pid, pat) in enumerate(rows):
        out[str(i)] = {
            "point": p, "layer_height": h, "mesh_normal": mn, "up_vector": u,
            "frame": {"point": p, "xaxis": xa, "yaxis": mn},
            "extruder_toggle": bool(on), "velocity": v, "wait_time": 0.0,
            "blend_radius": 0.0, "closest_support_pt": None, "distance_to_support": None,
            "is_feasible": True,
            "attributes": {"width_mm": w, "layer": lay, "path": pid, "pattern": pat},
        }
    return out


def printpoints_json(toolpath: Toolpath) -> str:
    """``printpoints`` as JSON text (what compas_slicer's ``save_to_json`` writes)."""
    return json.dumps(printpoints(toolpath))


def waypoints_csv(toolpath: Toolpath) -> str:
    """Every waypoint as one CSV row with a header line (columns ``CSV_COLUMNS``)."""
    n = len(toolpath)
    cols = np.column_stack([
        np.arange(n), toolpath.layer, toolpath.path, toolpath.position, toolpath.normal,
        toolpath.width, toolpath.height, toolpath.speed, toolpath.extrude.astype(int),
        toolpath.pattern,
    ])
    buf = io.StringIO()
    buf.write(",".join(CSV_COLUMNS) + "\n")
    fmt = ["%d"] * 3 + ["%.6f"] * 9 + ["%d"] * 2
    np.savetxt(buf, cols, fmt=fmt, delimiter=",")
    return buf.getvalue()
