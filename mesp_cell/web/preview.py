"""Preview data of a job's toolpath for the console's 3D view: the curved layers as polylines.

The waypoints are thinned evenly to at most ``max_points`` (a browser draws ~100 k line
vertices smoothly); a ``null`` separates two extrusion paths so the view never draws a travel
move as deposited material.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from core.errors import InputError


def toolpath_preview(job_dir: Path, max_points: int = 60_000) -> dict[str, Any]:
    """``{"layers", "x", "y", "z", "layer", "width", "speed"}`` of the depositing waypoints
    (mm, mm, mm/s), paths separated by ``None`` entries. An InputError when not sliced yet."""
    path = Path(job_dir) / "toolpath.npz"
    if not path.is_file():
        raise InputError("the job has no toolpath yet", "wait until it is sliced")
    with np.load(path) as z:
        pos = np.asarray(z["position"], dtype=np.float64)
        layer = np.asarray(z["layer"], dtype=np.int64)
        pid = np.asarray(z["path"], dtype=np.int64)
        width = np.asarray(z["width"], dtype=np.float64)
        speed = np.asarray(z["speed"], dtype=np.float64)
        ext = np.asarray(z["extrude"], dtype=bool)
    keep = np.flatnonzero(ext)
    step = max(1, int(np.ceil(len(keep) / max_points)))
    # thin within the kept waypoints, but keep every path's first and last one
    first = np.r_[True, pid[keep][1:] != pid[keep][:-1]]
    last = np.r_[first[1:], True]
    sel = keep[(np.arange(len(keep)) % step == 0) | first | last]
    brk = np.r_[False, pid[sel][1:] != pid[sel][:-1]]  # a new path starts here

    def col(values: np.ndarray, digits: int) -> list[Any]:
        vals: np.ndarray = np.round(values[sel], digits).astype(object)
        out: list[Any] = np.insert(vals, np.flatnonzero(brk), np.array(None, dtype=object)).tolist()
        return out

    return {"layers": int(layer.max()) + 1 if len(layer) else 0,
            "x": col(pos[:, 0], 3), "y": col(pos[:, 1], 3), "z": col(pos[:, 2], 3),
            "layer": col(layer, 0), "width": col(width, 3), "speed": col(speed, 2)}
