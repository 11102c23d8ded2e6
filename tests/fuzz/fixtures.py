"""Tiny valid inputs the malformed cases start from: a 20 mm cube, a sliced-looking job
directory (a planar toolpath of a 5 x 5 x 3 mm box and its model.ply), a valid launch file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from core.artifacts import save_npz
from core.stages import Toolpath


def cube_stl(path: Path, size_mm: float = 20.0) -> Path:
    """A closed cube of ``size_mm``, corner at the origin, as a binary STL."""
    box = trimesh.creation.box(extents=[size_mm] * 3)
    box.apply_translation([size_mm / 2] * 3)
    path.parent.mkdir(parents=True, exist_ok=True)
    box.export(path)
    return path


def toolpath_arrays(n: int = 40) -> dict[str, np.ndarray]:
    """A valid straight-line toolpath of ``n`` waypoints in two layers (mm, mm/s)."""
    x = np.linspace(0.0, 4.0, n)
    layer = (np.arange(n) >= n // 2).astype(np.int32)
    return {
        "position": np.column_stack([x, np.full(n, 2.0), 0.3 + 0.6 * layer]),
        "normal": np.tile([0.0, 0.0, 1.0], (n, 1)),
        "layer": layer,
        "path": layer.copy(),
        "height": np.full(n, 0.6),
        "width": np.full(n, 1.0),
        "speed": np.full(n, 10.0),
        "extrude": np.ones(n, dtype=bool),
        "pattern": np.zeros(n, dtype=np.int8),
    }


def job_dir(root: Path, arrays: dict[str, np.ndarray] | None = None) -> Path:
    """A job directory with toolpath.npz (``arrays`` written as given) and model.ply."""
    root.mkdir(parents=True, exist_ok=True)
    data = toolpath_arrays() if arrays is None else arrays
    save_npz(root / Toolpath.FILE, data)
    box = trimesh.creation.box(extents=[5.0, 5.0, 3.0])
    box.apply_translation([2.5, 2.5, 1.5])
    box.export(root / "model.ply")
    return root


LAUNCH_OK = """\
[cell]
name = "fuzz"
[bus]
hub = "tcp/127.0.0.1:auto"
[[process]]
name = "sleeper"
module = "mesp_cell.nodes.slicer_node"
restart = "never"
heartbeat_timeout = 5.0
[process.params]
slice_fn = ""
"""
