"""How long the supervisor waits for a job's slicing and planning: sized to the job.

A fixed hour let a job whose slicer died wait an hour before failing, and the queue behind it
with it. The wait is estimated from the work instead, with a wide margin for a loaded host:
slicing from the tets and layers the model needs (``slicer.budget``), planning from the
toolpath's waypoints. The model is read here first, so a model the slicer cannot read fails
the job at once with the reason.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

#: Seconds at least, per estimated tet, per estimated layer (slicing): a 20 mm cube (about
#: 39 k tets, 35 layers) gets 217 s; it slices in about 30 s on a loaded 2-core host.
SLICE_BASE_S, SLICE_PER_TET_S, SLICE_PER_LAYER_S = 120.0, 1e-3, 1.0
#: Seconds at least and per waypoint (planning).
PLAN_BASE_S, PLAN_PER_WAYPOINT_S = 120.0, 0.02
#: The wait is never longer than this (s).
MAX_WAIT_S = 4 * 3600.0
_TET_VOLUME = 1.0 / (6.0 * math.sqrt(2.0))  # regular tet of edge 1


def slice_timeout(model: Path, job_file: Path | None) -> float:
    """Seconds to wait for slicing ``model`` with ``job_file``; an ``InputError`` if either
    cannot be read (the job then fails before the slicer is asked)."""
    from slicer.budget import layer_estimate
    from slicer.config import load_job
    from slicer.mesh_io import TET_SUFFIXES, load_surface, load_tet_mesh

    job = load_job(job_file)
    if Path(model).suffix.lower() in TET_SUFFIXES:
        mesh = load_tet_mesh(model, job.model)
        tets = len(mesh.tets)
        size = mesh.vertices.max(axis=0) - mesh.vertices.min(axis=0)
        bbox = (float(size[0]), float(size[1]), float(size[2]))
    else:
        surface = load_surface(model, job.model)
        tets = int(abs(surface.volume_mm3) / (_TET_VOLUME * job.mesh.edge_length_mm**3))
        bbox = surface.bbox_mm
    layers = layer_estimate(bbox, job.slicing.layer_height_mm)
    wait = SLICE_BASE_S + SLICE_PER_TET_S * tets + SLICE_PER_LAYER_S * layers
    return min(wait, MAX_WAIT_S)


def plan_timeout(job_dir: Path) -> float:
    """Seconds to wait for planning the toolpath in ``job_dir`` (by its waypoints)."""
    from core.stages import Toolpath

    try:
        with np.load(Path(job_dir) / Toolpath.FILE, mmap_mode="r") as data:
            waypoints = len(data["position"])
    except (OSError, ValueError, KeyError):
        waypoints = 0  # the planner refuses the file itself, with its reason
    return min(PLAN_BASE_S + PLAN_PER_WAYPOINT_S * waypoints, MAX_WAIT_S)
