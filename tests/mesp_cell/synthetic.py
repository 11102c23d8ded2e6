"""Synthetic job artifacts for the runtime tests: a tiny toolpath and a matching trajectory.

``slice_job``/``plan_job`` have the signatures of ``mesp_cell.nodes.adapters`` so a launch can
name them (``slice_fn``/``plan_fn``) and run the whole cell without the real pipeline.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from core.artifacts import save_npz
from core.stages import Toolpath

if TYPE_CHECKING:
    from mesp_cell.cell_client import CellClient
    from mesp_cell.launcher import Launch

HOME = np.radians([0.0, -100.0, 100.0, -90.0, -90.0, 0.0])
LAYERS = 3
PER_LAYER = 12  # waypoints per layer
STEP = 4        # trajectory samples per waypoint
RATE_HZ = 100.0  # trajectory sample rate
TRAVEL = 12     # non-depositing samples between layers


def toolpath(rate: float | None = None, layers: int = LAYERS) -> Toolpath:
    """LAYERS square-ish contours of PER_LAYER waypoints, 0.6 mm apart in z.

    With ``rate`` (mm^3/s, the extruder's C) the width makes the toolpath's volume the ink the
    cell extrudes along ``trajectory_arrays`` (STEP / RATE_HZ s of deposition per waypoint),
    as a real plan's is; else 1.2 mm."""
    n = layers * PER_LAYER
    layer = np.repeat(np.arange(layers), PER_LAYER).astype(np.int32)
    ang = np.tile(np.linspace(0.0, 2 * np.pi, PER_LAYER, endpoint=False), layers)
    pos = np.stack([10 * np.cos(ang), 10 * np.sin(ang), 0.6 * layer], axis=1)
    normal = np.tile([0.0, 0.0, 1.0], (n, 1))
    width = 1.2
    if rate is not None:  # PER_LAYER waypoints of deposition over PER_LAYER - 1 segments
        seg = float(np.linalg.norm(pos[1] - pos[0]))
        width = rate * PER_LAYER * STEP / RATE_HZ / ((PER_LAYER - 1) * seg * 0.6)
    return Toolpath(position=pos, normal=normal, layer=layer, path=layer.copy(),
                    height=np.full(n, 0.6), width=np.full(n, width), speed=np.full(n, 9.0),
                    extrude=np.ones(n, bool), pattern=np.zeros(n, np.int8))


def trajectory_arrays(n_waypoints: int, q_offset: float = 0.0,
                      layers: int = LAYERS) -> dict[str, np.ndarray]:
    """A smooth joint motion around HOME that passes every waypoint in order.

    Layer l's waypoints follow each other every STEP samples; TRAVEL samples without
    deposition separate layers. ``q_offset`` (rad) shifts joint 1 (tests of bad trajectories).
    """
    rows_wp, rows_ex = [], []
    for l in range(layers):
        for i in range(PER_LAYER):
            rows_wp += [l * PER_LAYER + i] + [-1] * (STEP - 1)
            rows_ex += [True] * STEP
        if l < layers - 1:
            rows_wp += [-1] * TRAVEL
            rows_ex += [False] * TRAVEL
    rows_wp += [-1]
    rows_ex += [False]
    wp = np.asarray(rows_wp, dtype=np.int32)
    M = wp.shape[0]
    t = np.arange(M) / RATE_HZ
    s = np.sin(2 * np.pi * t / t[-1])[:, None]
    q = HOME + 0.15 * s * np.array([1.0, 0.5, -0.5, 0.3, 0.2, 0.1])
    q[:, 0] += q_offset
    qd = np.gradient(q, t, axis=0)
    assert int(wp.max()) + 1 == n_waypoints
    return {"t": t, "q": q, "qd": qd, "tcp": np.zeros((M, 3)), "waypoint": wp,
            "alpha": np.full(M, 90.0), "extrude": np.asarray(rows_ex, bool),
            "base_T": np.eye(4), "tool_T": np.eye(4), "model_T": np.eye(4)}


def slice_job(model: Path, job_file: Path | None, out_dir: Path, cell: str,
              cell_file: Path | None = None) -> dict[str, Any]:
    """Stands in for the slicing pipeline: refuses a missing model, writes toolpath.npz and
    records the cell's active extrusion profile."""
    from core.errors import InputError
    from mesp_cell.profiles import active

    if not Path(model).is_file():
        raise InputError(f"model {model} does not exist", "check the path")
    profile = active(cell)
    toolpath(profile.rate_mm3_s).save(Path(out_dir))
    profile.save_to_job(Path(out_dir))  # the cell's calibration, as the real slicer
    return {}


def plan_job(job_dir: Path, cell_file: Path | None) -> dict[str, Any]:
    """Stands in for the planner: writes a trajectory through every waypoint.

    With a cell file, the real planner runs instead (the placement-refusal tests need it).
    """
    if cell_file is not None:
        from mesp_cell.nodes import adapters

        return adapters.plan_job(job_dir, cell_file)
    save_npz(Path(job_dir) / "trajectory.npz", trajectory_arrays(LAYERS * PER_LAYER))
    return {}


LONG_LAYERS = 12  # the fault tests' job: 4x the deposition, so a stop's blob weighs less


def slice_long(model: Path, job_file: Path | None, out_dir: Path, cell: str,
               cell_file: Path | None = None) -> dict[str, Any]:
    """``slice_job`` with LONG_LAYERS layers."""
    from mesp_cell.profiles import active

    profile = active(cell)
    toolpath(profile.rate_mm3_s, LONG_LAYERS).save(Path(out_dir))
    profile.save_to_job(Path(out_dir))
    return {}


def plan_long(job_dir: Path, cell_file: Path | None) -> dict[str, Any]:
    """``plan_job`` for ``slice_long``'s toolpath."""
    save_npz(Path(job_dir) / "trajectory.npz",
             trajectory_arrays(LONG_LAYERS * PER_LAYER, layers=LONG_LAYERS))
    return {}


def write_cube(path: Path, size_mm: float = 20.0) -> Path:
    """A closed cube STL of ``size_mm`` (the model a submission loads and checks)."""
    import trimesh

    trimesh.creation.box(extents=[size_mm] * 3).export(path)
    return path


class WorkerKilled(BaseException):
    """Not an Exception: nothing on the bus worker's way catches it, so its thread dies."""


def slice_by_name(model: Path, job_file: Path | None, out_dir: Path, cell: str,
                  cell_file: Path | None = None) -> dict[str, Any]:
    """``slice_job``, except for a model named ``exits*`` (a library calling ``sys.exit``, as
    meshio does on a garbage .vtu) or ``kills*`` (an error that kills the worker thread)."""
    import sys

    if Path(model).name.startswith("exits"):
        sys.exit(1)
    if Path(model).name.startswith("kills"):
        raise WorkerKilled("the worker thread dies")
    return slice_job(model, job_file, out_dir, cell, cell_file)


@contextlib.contextmanager
def cell_in_home(home: Path, **overrides: Any) -> Iterator[Launch]:
    """The bundled sim cell with the synthetic slicer and planner (``overrides`` on top),
    running with ``home`` as its MESP_HOME; the environment is restored afterwards."""
    from mesp_cell.launcher import start_cell

    old = os.environ.get("MESP_HOME")
    os.environ["MESP_HOME"] = str(home)
    # a servo overrun watchdog that a loaded 2-core test host does not trip (a stall that
    # interrupts a print is not what these tests inject)
    launch = start_cell(overrides={"servo_overrun_s": 1.0,
                                   "slice_fn": "tests.mesp_cell.synthetic:slice_job",
                                   "plan_fn": "tests.mesp_cell.synthetic:plan_job",
                                   "prime_s": 0.1, **overrides})
    try:
        yield launch
    finally:
        launch.stop()
        if old is None:
            os.environ.pop("MESP_HOME", None)
        else:
            os.environ["MESP_HOME"] = old


def abort_unfinished(client: CellClient, timeout: float = 30.0) -> None:
    """Reset a latched e-stop, abort every job of the cell that has not ended and wait until
    each has: a job a failed test left interrupted holds the tank, and the next test's job
    would wait in ``planned`` behind it (one failure became four)."""
    from mesp_cell.jobs import FINAL

    client.reset_estop()
    left = [j.id for j in client.store.query(client.cell) if j.state not in FINAL]
    for job_id in left:
        client.command("abort", job_id)
    end = time.monotonic() + timeout
    while left and time.monotonic() < end:
        left = [j for j in left if client.status(j).state not in FINAL]
        time.sleep(0.05)
    assert not left, f"jobs {left} were not aborted within {timeout} s"
