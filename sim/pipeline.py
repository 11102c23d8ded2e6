"""The virtual print of a sliced job: the ``mesp inspect`` pipeline as a library call.

``inspect_job`` deposits DIR/toolpath.npz into the support gel on a voxel grid
(``sim.deposition``) and measures it against DIR/model.ply (``sim.metrics``); optionally also
the print as the planned trajectory moves the nozzle (``sim.as_planned``) and a planar or
commercial baseline side by side (``sim.baseline_prints``). It adds the "inspect" section to
DIR/report.json, writes the inspect_*.png pictures and returns the section with the columns
of the comparison table.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, NamedTuple

import numpy as np
import trimesh

from core.errors import InputError
from core.progress import Progress, StageTimer
from core.report import read_report, update_report
from core.stages import Toolpath
from planner.flow import PlannedSpeeds
from planner.trajectory import Trajectory
from sim.as_planned import (
    SLOWED,
    Slowdown,
    effective_speed,
    segment_speeds,
    slowdown,
    synced_segment_ink,
)
from sim.baseline_prints import BaselineOptions, flushed, gcode_print, planar_print, prusa_print
from sim.deposition import Deposit, DepositionConfig, covering_grid, deposit
from sim.inspect_figures import ct_slices, error_map, layer_plot, slowdown_plot
from sim.metrics import Quality, inspect_deposit
from sim.print_summary import PrintSummary
from sim.voxel_choice import NoNotes, Notes, auto_voxel
from slicer.extrusion import PROFILE_FILE, ExtrusionProfile, load_profile
from slicer.profiles import FACTORY


@dataclass(frozen=True)
class InspectOptions:
    """What to simulate besides the job's own print.

    Attributes:
        voxel_mm: voxel edge, mm (None: ``DEFAULT_VOXEL_MM``, coarser for large models).
        profile: extrusion profile name or TOML path (None: the job's DIR/profile.toml).
        baseline: the baseline toolpath to print beside it (``sim.baseline_prints``).
        flush: move the job's exposed waypoints inwards first (needs DIR/tetmesh.npz).
        as_planned: also print at the speeds of DIR/trajectory.npz.
        constant_flow: with ``as_planned``, the extruder keeps its rate where the arm slows.
        flow_lead_s: with ``as_planned``, how far ahead the synced rate is commanded, s.
        flow_tau_s: with ``as_planned``, the extruder's first-order time constant, s.
        figures: write the inspect_*.png pictures.
    """

    voxel_mm: float | None = None
    profile: str | None = None
    baseline: BaselineOptions = field(default_factory=BaselineOptions)
    flush: bool = False
    as_planned: bool = False
    constant_flow: bool = False
    flow_lead_s: float = 0.3
    flow_tau_s: float = 0.2
    figures: bool = True


class SimulatedPrint(NamedTuple):
    """One simulated print: the deposit, its quality and the report's summary of it."""

    deposit: Deposit
    quality: Quality
    summary: dict[str, Any]


class Inspection(NamedTuple):
    """What ``inspect_job`` produced.

    Attributes:
        section: the "inspect" section written to report.json.
        columns: (label, summary) per simulated print, for the side-by-side table.
    """

    section: dict[str, Any]
    columns: list[tuple[str, PrintSummary]]


def inspect_job(job: Path, options: InspectOptions, progress: Progress | None = None,
                notes: Notes | None = None) -> Inspection:
    """Simulate and measure the job in ``job`` (see the module docstring).

    ``notes`` receives lines for the operator (a coarsened voxel, an ignored --flush).

    Raises:
        InputError: a file of the job is missing or unreadable, or the options do not fit it.
    """
    timer = StageTimer(progress)
    notes = notes if notes is not None else NoNotes()
    with timer.stage("load"):
        toolpath = Toolpath.load(job)
        vertices, faces = load_model(job / "model.ply")
        morphology = job_profile(options.profile, job)
    voxel = options.voxel_mm if options.voxel_mm is not None else auto_voxel(vertices, notes)
    config = DepositionConfig(voxel_mm=float(voxel))
    flush: dict[str, Any] | None = None
    if options.flush and "flush" in read_report(job).get("toolpath", {}):
        # The cap of a move is relative to the current position: flushing twice would move
        # capped waypoints further, so a toolpath flushed by mesp slice is taken as it is.
        notes.info("note: the toolpath was already flushed by mesp slice; --flush ignored")
    elif options.flush:
        with timer.stage("flush"):
            toolpath, flush = flushed(job, toolpath, morphology)
    planned, trajectory = planned_speeds(job, toolpath) if options.as_planned else (None, None)
    slowed: Slowdown | None = None
    result = simulate("multi-axis", toolpath, morphology, vertices, faces, config, timer)
    section: dict[str, Any] = {**result.summary, "voxel_mm": config.voxel_mm,
                               "profile": morphology.name}
    if planned is not None and trajectory is not None:
        rate = float(morphology.rate_mm3_s)
        ink = None if options.constant_flow else synced_segment_ink(
            toolpath, trajectory, planned, rate, lead_s=options.flow_lead_s,
            tau_s=options.flow_tau_s)
        speed = planned.speed if ink is None else effective_speed(toolpath, planned, ink, rate)
        as_planned = simulate("as planned", toolpath, morphology, vertices, faces, config,
                              timer, speed)
        slowed = slowdown(toolpath, planned, morphology, ink)
        flow: dict[str, Any] = {"flow": "constant" if ink is None else "synced"}
        if ink is not None:
            flow.update(flow_lead_s=options.flow_lead_s, flow_tau_s=options.flow_tau_s)
        section["as_planned"] = {**as_planned.summary, **slowed.summary(), **flow}
    if flush is not None:
        section["flush"] = flush
    base = _baseline(job, options.baseline, toolpath, morphology, vertices, faces, config,
                     timer, section)
    if base is not None:
        section["comparison"] = comparison(PrintSummary.from_dict(result.summary),
                                           PrintSummary.from_dict(base.summary))
    if options.figures:
        with timer.stage("figures"):
            section["figures"] = figures(job, result, base)
            if slowed is not None:
                synced = section["as_planned"]["flow"] == "synced"
                section["figures"].append(slowdown_figure(job, slowed, synced))
    section["timing_s"] = {k: round(v, 3) for k, v in timer.seconds.items()}
    update_report(job, {"inspect": section})
    columns = [("multi-axis", PrintSummary.from_dict(result.summary))]
    if "as_planned" in section:
        columns.append(("as planned", PrintSummary.from_dict(section["as_planned"])))
    if "baselines" in section:
        columns += [(f"planar-{m}", PrintSummary.from_dict(b))
                    for m, b in section["baselines"].items()]
    elif base is not None:
        columns.append((section["baseline"].get("kind", "baseline"),
                        PrintSummary.from_dict(base.summary)))
    return Inspection(section, columns)


def _baseline(job: Path, options: BaselineOptions, toolpath: Toolpath,
              morphology: ExtrusionProfile, vertices: np.ndarray, faces: np.ndarray,
              config: DepositionConfig, timer: StageTimer, section: dict[str, Any]
              ) -> SimulatedPrint | None:
    """The baseline's print (None without one); its summaries go into ``section``."""
    if options.gcode is not None:
        with timer.stage("baseline toolpath"):
            base_tp, base_info = gcode_print(options, morphology, vertices)
        base = simulate("baseline", base_tp, morphology, vertices, faces, config, timer)
        section["baseline"] = {**base_info, **base.summary}
        return base
    if options.kind == "prusaslicer":
        with timer.stage("baseline toolpath (prusaslicer)"):
            base_tp, base_info = prusa_print(options, job, toolpath, morphology, vertices,
                                             faces)
        base = simulate("baseline prusaslicer", base_tp, morphology, vertices, faces, config,
                        timer)
        section["baseline"] = {**base_info, **base.summary}
        return base
    if options.kind != "planar":
        return None
    modes: list[Literal["overlap", "volume"]] = (
        ["overlap", "volume"] if options.width == "both" else [options.width])
    tried: dict[str, tuple[SimulatedPrint, dict[str, Any]]] = {}
    for mode in modes:
        with timer.stage(f"baseline toolpath ({mode})"):
            base_tp, base_info = planar_print(options, job, mode, toolpath, morphology,
                                              vertices, faces)
        run = simulate(f"baseline {mode}", base_tp, morphology, vertices, faces, config, timer)
        tried[mode] = (run, {**base_info, **run.summary})
    # The honest baseline is the best planar print, by mean surface error.
    best = min(tried, key=lambda m: tried[m][1]["surface_error_mm"]["mean"])
    section["baseline"] = {**tried[best][1],
                           "chosen": "lowest mean surface error of " + ", ".join(modes)}
    section["baselines"] = {m: t[1] for m, t in tried.items()}
    return tried[best][0]


def load_model(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V, 3) float64 mm, faces (F, 3) int64) of the job's model.ply."""
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for a broken file
        raise InputError(f"{path} is not a readable mesh ({exc})", "re-run mesp slice") from exc
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64)
    if faces.ndim != 2 or len(faces) == 0:
        raise InputError(f"{path} has no triangles", "re-run mesp slice")
    vertices = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=np.float64)
    return vertices, faces


def job_profile(name: str | None, job: Path) -> ExtrusionProfile:
    """The extrusion profile ``name``, else the job's own (DIR/profile.toml), else the
    factory profile."""
    recorded = job / PROFILE_FILE
    chosen = name or (str(recorded) if recorded.is_file() else FACTORY)
    return load_profile(chosen)


def planned_speeds(job: Path, toolpath: Toolpath) -> tuple[PlannedSpeeds, Trajectory]:
    """(``sim.as_planned.segment_speeds``, the trajectory) of DIR/trajectory.npz (one-line
    errors if unusable)."""
    try:
        trajectory = Trajectory.load(job)
    except InputError as exc:  # unreadable, or an array missing: name the stage that writes it
        raise InputError(exc.problem, f"re-run mesp plan {job}") from exc
    except (OSError, ValueError, KeyError) as exc:
        raise InputError(f"{job / 'trajectory.npz'} is not a readable trajectory ({exc})",
                         f"re-run mesp plan {job}") from exc
    return segment_speeds(toolpath, trajectory), trajectory


def simulate(label: str, toolpath: Toolpath, morphology: ExtrusionProfile,
             vertices: np.ndarray, faces: np.ndarray, config: DepositionConfig,
             timer: StageTimer, segment_speed: np.ndarray | None = None) -> SimulatedPrint:
    """Deposit ``toolpath`` (at ``segment_speed`` (S,) mm/s where given) and measure it."""
    bounds = np.stack([vertices.min(axis=0), vertices.max(axis=0)])
    with timer.stage(f"{label} deposition"):
        grid = covering_grid(toolpath, morphology, bounds, config,
                             segment_speed=segment_speed)
        dep = deposit(toolpath, morphology, config, grid=grid, progress=timer.progress,
                      segment_speed=segment_speed)
    with timer.stage(f"{label} metrics"):
        quality = inspect_deposit(dep, vertices, faces, toolpath)
    summary = quality.summary()
    summary.update({
        "commanded_volume_mm3": dep.commanded_mm3,
        "volume_conservation_error": dep.volume_error,
        "deposition_status": dep.status,
        "grid_shape": list(dep.grid.shape),
        "waypoints": len(toolpath),
        "layers": int(np.unique(toolpath.layer).size),
    })
    return SimulatedPrint(dep, quality, summary)


def figures(job: Path, result: SimulatedPrint, base: SimulatedPrint | None) -> list[str]:
    """The CT slices, error maps and per-layer plot of the print (and the baseline's)."""
    files = [
        ct_slices(job / "inspect_ct.png", result.deposit, result.quality,
                  "multi-axis: simulated CT slices"),
        error_map(job / "inspect_error_map.png", result.quality,
                  "multi-axis: surface error on the model"),
    ]
    if base is not None:
        files.append(ct_slices(job / "inspect_baseline_ct.png", base.deposit,
                               base.quality, "baseline: simulated CT slices"))
        files.append(error_map(job / "inspect_baseline_error_map.png", base.quality,
                               "baseline: surface error on the model"))
    files.append(layer_plot(job / "inspect_layers.png", result.quality,
                            base.quality if base else None))
    return [p.name for p in files]


def slowdown_figure(job: Path, slow: Slowdown, synced: bool) -> str:
    """inspect_as_planned.png: per layer, the slowed share of the path and its extra ink
    (``sim.as_planned.Slowdown``)."""
    return slowdown_plot(job / "inspect_as_planned.png", slow.layer, slow.length, slow.ratio,
                         slow.extra_mm3, SLOWED, synced).name


def comparison(main: PrintSummary, base: PrintSummary) -> dict[str, Any]:
    """Side by side with the paper's measurements (section 5.3, aorta and socket prints)."""
    return {
        "surface_error_mean_mm": {"multi_axis": main.surface_error_mm["mean"],
                                  "baseline": base.surface_error_mm["mean"],
                                  "paper_multi_axis": 0.20, "paper_planar": 0.49},
        "infill_ratio": {"multi_axis": main.infill_ratio, "baseline": base.infill_ratio},
        "interior_infill_ratio": {"multi_axis": main.interior_infill_ratio,
                                  "baseline": base.interior_infill_ratio,
                                  "paper_multi_axis": 0.9947},
        "pore_ratio": {"multi_axis": main.pore_ratio, "baseline": base.pore_ratio,
                       "paper_multi_axis": 0.0025},
        "over_deposition": {"multi_axis": main.over_deposition,
                            "baseline": base.over_deposition},
    }
