"""`mesp inspect DIR`: simulated deposition of a sliced job and its print quality."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from core.errors import InputError

DEFAULT_VOXEL_MM = 0.25
# Voxels of the default grid: the socket (137 x 125 x 212 mm) at 0.35 mm, ~40 s and ~4.3 GB.
AUTO_VOXEL_BUDGET = 100_000_000


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``inspect`` sub-command."""
    p = subparsers.add_parser(
        "inspect",
        help="simulate the deposition of a sliced job: infill, pores, surface error",
        description=(
            "Virtual print of DIR/toolpath.npz into the support gel on a voxel grid (constant "
            "extrusion rate, filament morphology from the extrusion profile, immiscible ink "
            "whose excess spreads into nearby free space), measured against DIR/model.ply: "
            "infill ratio, pore ratio, over-deposition, surface error (mean, p95, max) and "
            "per-layer over/under-deposition. Optionally the same for a planar baseline "
            "(--baseline planar: planar layers at the job's median layer height, in both line "
            "width modes, overlap W = beta w_f and volume-preserving W = C / (H v), the latter "
            "flushed like a curved job when DIR has tetmesh.npz; the better one is the baseline), "
            "PrusaSlicer's print of DIR/model.ply (--baseline prusaslicer: same layer height, "
            "lines at the overlap W = beta w_f, one constant speed, 100% rectilinear infill, "
            "G-code written to DIR/baseline_prusaslicer.gcode; `make baselines` installs "
            "PrusaSlicer) or a commercial slicer's G-code (--gcode FILE), side by side. "
            "With --as-planned also the print as DIR/trajectory.npz moves the nozzle: where "
            "the planner slows down, the cell scales the extruder's rate with the arm's speed "
            "(lead-compensated, the screw's first-order lag simulated), or, with "
            "--constant-flow, keeps C and deposits more. "
            "Adds an 'inspect' section to DIR/report.json and writes inspect_*.png into DIR."
        ),
    )
    p.add_argument("dir", metavar="DIR", type=Path, help="job directory written by `mesp slice`")
    p.add_argument("--voxel", type=float, default=None, metavar="MM",
                   help=f"voxel edge in mm (default {DEFAULT_VOXEL_MM}, coarser for models too "
                        f"large for {AUTO_VOXEL_BUDGET:,} voxels)")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--baseline", choices=["planar", "prusaslicer"],
                       help="also print the model with planar layers (our planar slicer, or "
                            "PrusaSlicer's CLI on the job's model) and compare")
    group.add_argument("--gcode", type=Path, metavar="FILE",
                       help="also print this planar G-code (Cura/PrusaSlicer) and compare")
    p.add_argument("--profile", default=None, metavar="NAME",
                   help="extrusion profile name or TOML path (default: the profile the job was "
                   "sliced with, DIR/profile.toml)")
    p.add_argument("--baseline-height", type=float, default=None, metavar="MM",
                   help="planar baseline layer height (default: median toolpath height)")
    p.add_argument("--baseline-beta", type=float, default=None, metavar="B",
                   help="planar baseline overlap ratio (default: sqrt(pi)/2, volume-matching, "
                        "in overlap mode and for PrusaSlicer; the profile's beta in volume "
                        "mode)")
    p.add_argument("--baseline-width", choices=["overlap", "volume", "both"], default="both",
                   help="planar baseline line width rule: W = beta w_f (overlap), "
                        "W = C / (H v) (volume), or both, keeping the better (default both; "
                        "PrusaSlicer always uses overlap)")
    p.add_argument("--flush", action="store_true",
                   help="first move the job's exposed waypoints inwards so filaments are flush "
                        "with the model (slicer.toolpath.flush; needs DIR/tetmesh.npz; ignored "
                        "when mesp slice already did it)")
    p.add_argument("--filament", type=float, default=1.75, metavar="MM",
                   help="filament diameter the G-code's E refers to (0 = volumetric E)")
    p.add_argument("--as-planned", action="store_true",
                   help="also print at the speeds the planned trajectory (DIR/trajectory.npz, "
                        "from mesp plan) moves each segment at, and compare")
    p.add_argument("--constant-flow", action="store_true",
                   help="with --as-planned: the extruder keeps its rate C where the arm slows "
                        "down (the cell scales it with the arm's speed)")
    p.add_argument("--flow-lead", type=float, default=0.3, metavar="S",
                   help="with --as-planned: how far ahead the rate is commanded (s, default "
                        "0.3: the launch files' lead_s)")
    p.add_argument("--flow-tau", type=float, default=0.2, metavar="S",
                   help="with --as-planned: time constant of the extruder's flow response "
                        "(s, default 0.2: the emulated extruder's)")
    p.add_argument("--no-figures", action="store_true", help="do not write the PNG pictures")
    p.add_argument("--quiet", action="store_true", help="no progress display")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute `mesp inspect`."""
    from core.progress import StageTimer
    from core.report import read_report, update_report
    from core.stages import Toolpath
    from mesp_cell.console import ConsoleProgress
    from sim.deposition import DepositionConfig

    job = Path(args.dir)
    if not job.is_dir():
        raise InputError(f"job directory {job} does not exist", "run mesp slice MODEL --out DIR")
    if not (job / Toolpath.FILE).is_file():
        raise InputError(f"{job} has no {Toolpath.FILE}", f"run mesp slice MODEL --out {job}")
    if not (job / "model.ply").is_file():
        # The model as sliced (mm, model frame): metrics and PrusaSlicer both need it.
        source = read_report(job).get("job", {}).get("model_file") or "MODEL"
        raise InputError(f"{job} has no model.ply (the model as mesp slice read it)",
                         f"re-run mesp slice {source} --out {job}")
    if args.voxel is not None and not (np.isfinite(args.voxel) and 0.01 <= args.voxel <= 10.0):
        raise InputError(f"--voxel {args.voxel} is out of range", "use 0.01 to 10 mm, e.g. 0.25")
    if args.flush and not (job / "tetmesh.npz").is_file():
        raise InputError(f"--flush needs {job / 'tetmesh.npz'}",
                         f"re-run mesp slice MODEL --out {job}")
    if args.as_planned and not (job / "trajectory.npz").is_file():
        raise InputError(f"--as-planned needs {job / 'trajectory.npz'}", f"run mesp plan {job}")
    for name, value in (("--flow-lead", args.flow_lead), ("--flow-tau", args.flow_tau)):
        if not (np.isfinite(value) and 0.0 <= value <= 10.0):
            raise InputError(f"{name} {value} is out of range", "use 0 to 10 s, e.g. 0.2")
    if args.gcode is not None and not Path(args.gcode).is_file():
        raise InputError(f"G-code file {args.gcode} does not exist", "check the --gcode path")
    if not (np.isfinite(args.filament) and 0.0 <= args.filament <= 10.0):
        raise InputError(f"--filament {args.filament} is out of range",
                         "use a diameter of 0 to 10 mm (0: E is a volume in mm^3)")
    for name, value, lo, hi in (("--baseline-height", args.baseline_height, 0.02, 20.0),
                                ("--baseline-beta", args.baseline_beta, 0.1, 1.0)):
        if value is not None and not lo <= value <= hi:
            raise InputError(f"{name} {value} is out of range", f"use {lo} to {hi}")
    if args.baseline == "prusaslicer":
        from sim.baseline import VOLUME_MATCHING_BETA
        from sim.commercial import PrusaConfig, find_prusaslicer

        # Before minutes of simulation, not after: PrusaSlicer is there, beta is in its range.
        find_prusaslicer()
        PrusaConfig(beta=args.baseline_beta or VOLUME_MATCHING_BETA)
    console = ConsoleProgress(quiet=args.quiet)
    timer = StageTimer(console)
    with timer.stage("load"):
        toolpath = Toolpath.load(job)
        vertices, faces = _load_model(job / "model.ply")
        morphology, profile_name = _load_morphology(args.profile, console, job)
    voxel = args.voxel if args.voxel is not None else _auto_voxel(vertices, console)
    config = DepositionConfig(voxel_mm=float(voxel))
    flush: dict[str, Any] | None = None
    if args.flush and "flush" in read_report(job).get("toolpath", {}):
        # The cap of a move is relative to the current position: flushing twice would move
        # capped waypoints further, so a toolpath flushed by mesp slice is taken as it is.
        console.info("note: the toolpath was already flushed by mesp slice; --flush ignored")
    elif args.flush:
        with timer.stage("flush"):
            toolpath, flush = _flush(job, toolpath, morphology)
    planned, trajectory = _planned_speeds(job, toolpath) if args.as_planned else (None, None)
    slowed = None
    result = _simulate("multi-axis", toolpath, morphology, vertices, faces, config, timer)
    section: dict[str, Any] = {**result["summary"], "voxel_mm": config.voxel_mm,
                               "profile": profile_name}
    if planned is not None and trajectory is not None:
        from sim.as_planned import effective_speed, slowdown, synced_segment_ink

        rate = float(morphology.rate_mm3_s)
        ink = None if args.constant_flow else synced_segment_ink(
            toolpath, trajectory, planned, rate, lead_s=args.flow_lead, tau_s=args.flow_tau)
        speed = planned.speed if ink is None else effective_speed(toolpath, planned, ink, rate)
        as_planned = _simulate("as planned", toolpath, morphology, vertices, faces, config,
                               timer, speed)
        slowed = slowdown(toolpath, planned, morphology, ink)
        flow = {"flow": "constant" if ink is None else "synced"}
        if ink is not None:
            flow.update(flow_lead_s=args.flow_lead, flow_tau_s=args.flow_tau)
        section["as_planned"] = {**as_planned["summary"], **slowed.summary(), **flow}
    if flush is not None:
        section["flush"] = flush
    base: dict[str, Any] | None = None
    if args.gcode:
        with timer.stage("baseline toolpath"):
            base_tp, base_info = _gcode_toolpath(args, morphology, vertices)
        base = _simulate("baseline", base_tp, morphology, vertices, faces, config, timer)
        section["baseline"] = {**base_info, **base["summary"]}
    elif args.baseline == "prusaslicer":
        with timer.stage("baseline toolpath (prusaslicer)"):
            base_tp, base_info = _prusaslicer_toolpath(args, job, toolpath, morphology,
                                                       vertices, faces)
        base = _simulate("baseline prusaslicer", base_tp, morphology, vertices, faces, config,
                         timer)
        section["baseline"] = {**base_info, **base["summary"]}
    elif args.baseline:
        modes = ["overlap", "volume"] if args.baseline_width == "both" else [args.baseline_width]
        tried: dict[str, dict[str, Any]] = {}
        for mode in modes:
            with timer.stage(f"baseline toolpath ({mode})"):
                base_tp, base_info = _planar_toolpath(args, job, mode, toolpath, morphology,
                                                      vertices, faces)
            run_ = _simulate(f"baseline {mode}", base_tp, morphology, vertices, faces, config,
                             timer)
            tried[mode] = {"run": run_, "summary": {**base_info, **run_["summary"]}}
        # The honest baseline is the best planar print, by mean surface error.
        best = min(tried, key=lambda m: tried[m]["summary"]["surface_error_mm"]["mean"])
        base = tried[best]["run"]
        section["baseline"] = {**tried[best]["summary"],
                               "chosen": "lowest mean surface error of " + ", ".join(modes)}
        section["baselines"] = {m: t["summary"] for m, t in tried.items()}
    if base is not None:
        section["comparison"] = _comparison(result["summary"], base["summary"])
    if not args.no_figures:
        with timer.stage("figures"):
            section["figures"] = _figures(job, result, base)
            if slowed is not None:
                synced = section["as_planned"]["flow"] == "synced"
                section["figures"].append(_slowdown_figure(job, slowed, synced))
    section["timing_s"] = {k: round(v, 3) for k, v in timer.seconds.items()}
    update_report(job, {"inspect": section})
    columns = [("multi-axis", result["summary"])]
    if "as_planned" in section:
        columns.append(("as planned", section["as_planned"]))
    if "baselines" in section:
        columns += [(f"planar-{m}", b) for m, b in section["baselines"].items()]
    elif base is not None:
        columns.append((section["baseline"].get("kind", "baseline"), base["summary"]))
    print(_table(columns))
    return 0


def _auto_voxel(vertices: np.ndarray, console: Any) -> float:
    """The default voxel, coarsened so the model's grid stays within the budget."""
    extent = np.ptp(vertices, axis=0) + 8.0  # the grid's padding and filament overhang
    need = float(np.prod(extent)) / AUTO_VOXEL_BUDGET
    voxel = max(DEFAULT_VOXEL_MM, float(np.ceil(100.0 * need ** (1.0 / 3.0))) / 100.0)
    if voxel > DEFAULT_VOXEL_MM:
        console.info(f"note: model is large; using --voxel {voxel:.2f} (pass --voxel to choose)")
    return voxel


def _load_model(path: Path) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for a broken file
        raise InputError(f"{path} is not a readable mesh ({exc})", "re-run mesp slice") from exc
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64)
    if faces.ndim != 2 or len(faces) == 0:
        raise InputError(f"{path} has no triangles", "re-run mesp slice")
    vertices = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=np.float64)
    return vertices, faces


def _load_morphology(name: str | None, console: Any, job: Path) -> tuple[Any, str]:
    """The extrusion profile (``name``, else the job's own, else the factory profile), or a
    plain ellipse model if slicer.extrusion is missing."""
    from sim.deposition import EllipseMorphology

    try:
        from slicer.extrusion import load_profile
    except ImportError:
        if name is not None:
            raise InputError("extrusion profiles are not available in this installation",
                             "drop --profile") from None
        console.info("note: no extrusion profile module; using a round filament "
                     "(sim.deposition.EllipseMorphology)")
        return EllipseMorphology(), "ellipse (default)"
    from slicer.extrusion import PROFILE_FILE
    from slicer.profiles import FACTORY

    recorded = job / PROFILE_FILE
    chosen = name or (str(recorded) if recorded.is_file() else FACTORY)
    profile = load_profile(chosen)
    return profile, profile.name


def _planned_speeds(job: Path, toolpath: Any) -> tuple[Any, Any]:
    """(sim.as_planned.segment_speeds, the trajectory) of DIR/trajectory.npz (one-line errors
    if unusable)."""
    from planner.trajectory import Trajectory
    from sim.as_planned import segment_speeds

    try:
        trajectory = Trajectory.load(job)
    except InputError as exc:  # unreadable, or an array missing: name the stage that writes it
        raise InputError(exc.problem, f"re-run mesp plan {job}") from exc
    except (OSError, ValueError, KeyError) as exc:
        raise InputError(f"{job / 'trajectory.npz'} is not a readable trajectory ({exc})",
                         f"re-run mesp plan {job}") from exc
    return segment_speeds(toolpath, trajectory), trajectory


def _simulate(label: str, toolpath: Any, morphology: Any, vertices: np.ndarray,
              faces: np.ndarray, config: Any, timer: Any,
              segment_speed: np.ndarray | None = None) -> dict[str, Any]:
    from sim.deposition import covering_grid, deposit
    from sim.metrics import inspect_deposit

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
    return {"deposit": dep, "quality": quality, "summary": summary}


def _flush(job: Path, toolpath: Any, morphology: Any) -> tuple[Any, dict[str, Any]]:
    """The toolpath with exposed filaments made flush (slicer.toolpath.flush) and its report."""
    from core.stages import TetMesh
    from slicer.toolpath.flush import flush_toolpath

    flushed, report = flush_toolpath(toolpath, TetMesh.load(job), morphology)
    return flushed, report.as_dict()


def _gcode_toolpath(args: argparse.Namespace, morphology: Any, vertices: np.ndarray
                    ) -> tuple[Any, dict[str, Any]]:
    from sim.gcode import GcodeOptions, align_to_bounds, read_gcode

    opts = GcodeOptions(filament_diameter_mm=args.filament,
                        rate_mm3_s=float(morphology.rate_mm3_s))
    tp = read_gcode(args.gcode, opts)
    bounds = np.stack([vertices.min(axis=0), vertices.max(axis=0)])
    # Filaments centred on the nozzle tip (sim.deposition): each layer around its cut plane.
    return align_to_bounds(tp, bounds, slab_middle=True), {"kind": "gcode",
                                                           "file": str(args.gcode)}


def _baseline_height(args: argparse.Namespace, toolpath: Any) -> float:
    """--baseline-height, else the median layer height of the job's extruding waypoints."""
    ext = toolpath.extrude
    return float(args.baseline_height or (np.median(toolpath.height[ext]) if ext.any()
                                          else 0.6))


def _prusaslicer_toolpath(args: argparse.Namespace, job: Path, toolpath: Any, morphology: Any,
                          vertices: np.ndarray, faces: np.ndarray
                          ) -> tuple[Any, dict[str, Any]]:
    """PrusaSlicer's print of the job's model (sim.commercial), moved onto the model."""
    from core.report import read_report
    from sim.baseline import VOLUME_MATCHING_BETA
    from sim.commercial import PrusaConfig, slice_with_prusaslicer

    cfg = PrusaConfig(layer_height_mm=_baseline_height(args, toolpath),
                      beta=args.baseline_beta or VOLUME_MATCHING_BETA)
    result = slice_with_prusaslicer(vertices, faces, morphology, cfg, job)
    info = result.info()
    # model.ply is the job's model as mesp slice read it (mm, model frame); name its source.
    source = read_report(job).get("job", {}).get("model_file")
    info["model_source"] = f"model.ply (from {source})" if source else "model.ply"
    return result.toolpath, info


def _planar_toolpath(args: argparse.Namespace, job: Path, mode: str, toolpath: Any,
                     morphology: Any, vertices: np.ndarray, faces: np.ndarray
                     ) -> tuple[Any, dict[str, Any]]:
    """Planar baseline in one width mode, flushed like a curved job when the tets are there."""
    from sim.baseline import VOLUME_MATCHING_BETA, PlanarConfig, planar_toolpath

    height = _baseline_height(args, toolpath)
    default_beta = VOLUME_MATCHING_BETA if mode == "overlap" else float(
        getattr(morphology, "beta", VOLUME_MATCHING_BETA))
    beta = args.baseline_beta or default_beta
    cfg = PlanarConfig(layer_height_mm=height, beta=beta, width_mode=mode)  # type: ignore[arg-type]
    tp = planar_toolpath(vertices, faces, morphology, cfg)
    info: dict[str, Any] = {"kind": "planar", "width_mode": mode,
                            "layer_height_mm": float(tp.height[0]), "beta": beta,
                            "width_mm": float(tp.width[0]), "speed_mm_s": float(tp.speed[0])}
    # The volume mode shares the curved toolpath's rules (h_f = H / beta, 2 H at beta 0.5), so
    # it gets the same flush. The overlap mode's filament barely exceeds H (0.04 mm at beta
    # 0.886) and is left as a commercial slicer makes it (flushing it measured slightly worse).
    if mode == "volume" and (job / "tetmesh.npz").is_file():
        tp, info["flush"] = _flush(job, tp, morphology)
    return tp, info


def _figures(job: Path, result: dict[str, Any], base: dict[str, Any] | None) -> list[str]:
    from sim.inspect_figures import ct_slices, error_map, layer_plot

    files = [
        ct_slices(job / "inspect_ct.png", result["deposit"], result["quality"],
                  "multi-axis: simulated CT slices"),
        error_map(job / "inspect_error_map.png", result["quality"],
                  "multi-axis: surface error on the model"),
    ]
    if base is not None:
        files.append(ct_slices(job / "inspect_baseline_ct.png", base["deposit"],
                               base["quality"], "baseline: simulated CT slices"))
        files.append(error_map(job / "inspect_baseline_error_map.png", base["quality"],
                               "baseline: surface error on the model"))
    files.append(layer_plot(job / "inspect_layers.png", result["quality"],
                            base["quality"] if base else None))
    return [p.name for p in files]


def _slowdown_figure(job: Path, slow: Any, synced: bool) -> str:
    """inspect_as_planned.png: per layer, the slowed share of the path and its extra ink
    (``sim.as_planned.Slowdown``)."""
    from sim.as_planned import SLOWED
    from sim.inspect_figures import slowdown_plot

    return slowdown_plot(job / "inspect_as_planned.png", slow.layer, slow.length, slow.ratio,
                         slow.extra_mm3, SLOWED, synced).name


def _comparison(main: dict[str, Any], base: dict[str, Any]) -> dict[str, Any]:
    """Side by side with the paper's measurements (section 5.3, aorta and socket prints)."""
    return {
        "surface_error_mean_mm": {"multi_axis": main["surface_error_mm"]["mean"],
                                  "baseline": base["surface_error_mm"]["mean"],
                                  "paper_multi_axis": 0.20, "paper_planar": 0.49},
        "infill_ratio": {"multi_axis": main["infill_ratio"], "baseline": base["infill_ratio"]},
        "interior_infill_ratio": {"multi_axis": main["interior_infill_ratio"],
                                  "baseline": base["interior_infill_ratio"],
                                  "paper_multi_axis": 0.9947},
        "pore_ratio": {"multi_axis": main["pore_ratio"], "baseline": base["pore_ratio"],
                       "paper_multi_axis": 0.0025},
        "over_deposition": {"multi_axis": main["over_deposition"],
                            "baseline": base["over_deposition"]},
    }


def _facing(summary: dict[str, Any], facing: str) -> float:
    """Signed mean surface error on the model faces facing ``facing`` (nan if none)."""
    part = summary.get("surface_error_by_facing", {}).get(facing)
    return float(part["signed_mean"]) if part and part["share"] > 0 else float("nan")


def _table(columns: list[tuple[str, dict[str, Any]]]) -> str:
    """Side-by-side table (one column per simulated print), with the paper's numbers."""
    rows = [
        ("infill ratio %", lambda s: 100 * s["infill_ratio"], "-"),
        ("interior infill % (1 mm)", lambda s: 100 * s["interior_infill_ratio"], "99.47 (CT)"),
        ("pore ratio %", lambda s: 100 * s["pore_ratio"], "0.25"),
        ("over-deposition %", lambda s: 100 * s["over_deposition"], "-"),
        ("under-deposition %", lambda s: 100 * s["under_deposition"], "-"),
        ("surface error mean mm", lambda s: s["surface_error_mm"]["mean"], "0.20 (planar 0.49)"),
        ("surface error p95 mm", lambda s: s["surface_error_mm"]["p95"], "-"),
        ("surface error max mm", lambda s: s["surface_error_mm"]["max"], "< 1.5"),
        # signed: > 0 the print bulges out of faces facing that way, < 0 it falls short
        ("  signed, up faces mm", lambda s: _facing(s, "up"), "-"),
        ("  signed, side faces mm", lambda s: _facing(s, "side"), "-"),
        ("  signed, down faces mm", lambda s: _facing(s, "down"), "-"),
    ]
    head = f"{'':24}" + "".join(f"{label:>16}" for label, _ in columns)
    lines = [head + f"   {'paper':<20}"]
    for name, get, paper in rows:
        line = f"{name:24}" + "".join(f"{get(summary):16.3f}" for _, summary in columns)
        lines.append(line + f"   {paper:<20}")
    return "\n".join(lines)
