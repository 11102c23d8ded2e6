"""Thin adapters from the slicer/planner nodes to the library functions.

A node calls ``slice_job`` / ``plan_job`` here; each can be replaced by a function named
``"module:function"`` in the node's parameters (``slice_fn``/``plan_fn``) with the same
signature, which the tests use to run the cell on synthetic artifacts. A slice function records
the extrusion profile it used in the job directory (``slicer.extrusion.PROFILE_FILE``).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from core.errors import InputError

SliceFn = Callable[[Path, Path | None, Path, str, Path | None], dict[str, Any]]
PlanFn = Callable[[Path, Path | None], dict[str, Any]]


def resolve(spec: str) -> Callable[..., dict[str, Any]]:
    """The function named ``"package.module:function"``."""
    module, _, name = spec.partition(":")
    if not module or not name:
        raise InputError(f"'{spec}' does not name a function", "write it as module:function")
    try:
        fn = getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError) as exc:
        raise InputError(f"cannot load {spec} ({exc})", "check the launch file") from exc
    return fn


def slice_job(model: Path, job_file: Path | None, out_dir: Path, cell: str,
              cell_file: Path | None = None) -> dict[str, Any]:
    """Slice ``model`` with the job file (None = defaults) into ``out_dir``; the report.

    The job's profile "active" is ``cell``'s active calibration (``mesp_cell.profiles``); the
    step limits follow the alpha range of the cell file the job is planned in (None = bundled),
    the speed ramps its path accelerations.
    """
    from mesp_cell import profiles
    from planner.cell import load_cell
    from slicer import pipeline
    from slicer.config import load_job

    model = Path(model)
    if not model.is_file():
        raise InputError(f"model {model} does not exist", "check the path")
    job = load_job(Path(job_file) if job_file else None)
    job = job.with_overrides(extrusion={"profile": profiles.resolve(job.extrusion.profile, cell)})
    planning = load_cell(Path(cell_file) if cell_file else None).planning
    report = pipeline.slice_model(model, Path(out_dir), job, alpha=planning.alpha_range,
                                  accel=planning.path_accel)
    _check_volume(report)
    return report


def _check_volume(report: dict[str, Any]) -> None:
    """A job whose toolpath lays more or less ink than the model by beyond the slicer's own
    limit (``slicer.checks.VOLUME_ERROR``) is refused before planning, with the slicer's note
    (its cause and fix): the cell never prints a part it knows is out of tolerance."""
    from slicer.checks import VOLUME_ERROR, job_notes
    from slicer.summary import SliceSummary

    error = SliceSummary.of(report).volume_error
    if error is None or abs(error) <= VOLUME_ERROR:
        return
    note = next((n for n in job_notes(report) if "deposited volume" in n), "")
    fix = note.split("fix: ", 1)[1] if "fix: " in note else (
        "see toolpath.per_layer in report.json; scale the model (--scale-to) or change the "
        "layer height")
    raise InputError(f"the toolpath deposits {100 * error:+.1f}% of the model's volume "
                     f"(limit {100 * VOLUME_ERROR:g}%)", fix)


def plan_job(job_dir: Path, cell_file: Path | None) -> dict[str, Any]:
    """Plan ``job_dir/toolpath.npz`` in the cell (None = bundled); writes trajectory.npz
    and the plan figures.

    A plan that does not reach every waypoint or breaks a limit is refused with its status,
    so nothing moves.
    """
    from core.report import update_report
    from core.stages import Toolpath
    from planner.cell import load_cell
    from planner.plan import plan
    from planner.status import PlanStatus

    job_dir = Path(job_dir)
    toolpath = Toolpath.load(job_dir)
    cell = load_cell(Path(cell_file) if cell_file else None)
    result = plan(toolpath, cell)
    if result.status is not PlanStatus.OK:
        raise InputError(f"plan refused ({result.status}): {result.message}",
                         "move the model (cell [placement]) or change the job")
    result.trajectory.save(job_dir)
    from planner.plots import write_plan_figures

    # the same plan_*.png `mesp plan` writes, so a job run through the cell can be looked at
    figures = write_plan_figures(result, job_dir / "figures")
    report = {**result.report, "figures": [str(p.relative_to(job_dir)) for p in figures]}
    update_report(job_dir, {"plan": report})
    return report
