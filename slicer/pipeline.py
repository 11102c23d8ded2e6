"""The slicing pipeline: model file -> TetMesh -> Field + Layers -> Toolpath, with report.

Each stage is computed from the previous stage's value and saved to its file in the job
directory as soon as it exists, so an interrupted run loses nothing already computed.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import tomli_w
import trimesh

from core.alpha_range import AlphaRange
from core.artifacts import atomic_write_bytes
from core.configtools import to_dict
from core.errors import InputError
from core.path_accel import PathAccel
from core.progress import Progress, StageTimer
from core.report import update_report
from core.stages import TetMesh
from core.tolerance import tol
from slicer.budget import check_budget
from slicer.config import JobConfig
from slicer.mesh_io import Surface

if TYPE_CHECKING:
    from slicer.layers import LayerExtraction, LayerSpacing
    from slicer.toolpath.results import ToolpathResult

Until = Literal["tetmesh", "layers", "toolpath"]


def slice_model(
    model: Path,
    out_dir: Path,
    job: JobConfig,
    progress: Progress | None = None,
    until: Until = "toolpath",
    alpha: AlphaRange | None = None,
    repair: bool = False,
    accel: PathAccel | None = None,
) -> dict[str, Any]:
    """Slice ``model`` into ``out_dir``; returns the report written to ``report.json``.

    ``alpha`` is the printing-angle range of the cell the job is for (None: the bundled cell's);
    the toolpath's step limits follow from it; ``accel`` its path accelerations (None: the
    bundled cell's), which the stripe joins' speed ramps keep. ``repair``: close an open
    surface or wrap a non-manifold one first (``slicer.repair``).
    """
    from slicer import mesh_io, tetrahedralize

    model = Path(model)
    out_dir = Path(out_dir)
    _prepare_out_dir(out_dir)
    timer = StageTimer(progress)
    t0 = time.perf_counter()
    report: dict[str, Any] = {"job": {"model_file": str(model), "config": to_dict(job)}}
    atomic_write_bytes(out_dir / "job.toml", tomli_w.dumps(to_dict(job)).encode())

    with timer.stage("load"):
        if model.suffix.lower() in mesh_io.TET_SUFFIXES:
            given: TetMesh | None = mesh_io.load_tet_mesh(model, units=job.model)
            surface = _boundary_surface(given, model)  # type: ignore[arg-type]
        elif repair:
            from slicer.repair import load_repaired

            given = None
            surface = load_repaired(model, units=job.model)
        else:
            given = None
            surface = mesh_io.load_surface(model, units=job.model)
        check_budget(surface.bbox_mm, job)
        _save_surface(surface, out_dir / "model.ply")
    report["model"] = {
        "volume_mm3": surface.volume_mm3,
        "bbox_mm": list(surface.bbox_mm),
        "repairs": list(surface.notes),
    }

    with timer.stage("tetrahedralize"):
        if given is None:
            from slicer.tet_cache import cache_dir

            tetmesh, stats = tetrahedralize.tetrahedralize(surface, job.mesh, progress,
                                                           cache=cache_dir())
            if stats.cached:  # against the surface as measured now (the union of its shells)
                stats = replace(stats, surface_volume_mm3=surface.volume_mm3,
                                volume_error=stats.volume_mm3 / surface.volume_mm3 - 1.0)
        else:
            tetmesh = given
            stats = tetrahedralize.quality(tetmesh.vertices, tetmesh.tets, surface.volume_mm3)
        tetmesh.save(out_dir)
    report["mesh"] = {
        "tets": len(tetmesh.tets),
        "vertices": len(tetmesh.vertices),
        "given": given is not None,
        **stats.as_dict(),
    }
    if until == "tetmesh":
        return _finish(out_dir, report, timer, t0)

    with timer.stage("slicing"):
        slicing_report, extraction = _slice(tetmesh, job, out_dir, progress)
    report["slicing"] = slicing_report
    if until == "layers":
        return _finish(out_dir, report, timer, t0)

    from slicer.toolpath.thin_features import ThinWallsError

    with timer.stage("toolpath"):
        try:
            report["toolpath"] = _toolpath(tetmesh, extraction, job, out_dir, surface,
                                           progress, alpha or AlphaRange.bundled(), accel)
        except ThinWallsError as exc:
            # refused before any toolpath file: the report marks the too-thin layers
            report["toolpath"] = exc.section
            _finish(out_dir, report, timer, t0)
            raise
    return _finish(out_dir, report, timer, t0)


def _boundary_surface(tetmesh: TetMesh, source: Path) -> Surface:
    """The closed boundary of a given tet mesh, outward oriented, as the model surface."""
    from slicer.operators import build_operators

    boundary = build_operators(tetmesh).boundary
    return Surface(vertices=tetmesh.vertices, faces=boundary.faces, source=source)


def _save_surface(surface: Surface, path: Path) -> None:
    """The model surface as sliced (mm, model frame), for inspection and viewers."""
    mesh = trimesh.Trimesh(surface.vertices, surface.faces, process=False)
    data = mesh.export(file_type="ply")
    atomic_write_bytes(path, data if isinstance(data, bytes) else str(data).encode())


def _prepare_out_dir(out_dir: Path) -> None:
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(
            f"cannot create {out_dir} ({exc.strerror})", "choose another --out"
        ) from exc
    probe = out_dir / ".write-test"
    try:
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise InputError(
            f"cannot write into {out_dir} ({exc.strerror})", "choose another --out"
        ) from exc


def _slice(
    tetmesh: TetMesh, job: JobConfig, out_dir: Path, progress: Progress | None
) -> tuple[dict[str, Any], LayerExtraction]:
    """Field optimisation and layer extraction, their files, pictures and report section."""
    from slicer import field as field_mod
    from slicer import figures, heights
    from slicer import layers as layers_mod
    from slicer.extrusion import load_profile
    from slicer.layer_export import export_layers_ply

    result = field_mod.compute_field(tetmesh, job.slicing, progress=progress)
    extraction = layers_mod.extract_layers(tetmesh, result, job.slicing, progress=progress)
    extraction.field.save(out_dir)
    extraction.layers.save(out_dir)
    export_layers_ply(extraction.layers, out_dir / "layers_ply")

    # Heights as printed: on the layers of the final field and, for the baseline, on the
    # layers the initial (harmonic) field would give at the same target (slicer.heights).
    final = heights.face_heights(extraction.layers)
    initial = heights.face_heights(heights.initial_layers(result,
                                                          extraction.layers.layer_count))
    lo, hi = load_profile(job.extrusion.profile).layer_height_range
    fig_dir = out_dir / "figures"
    fig_dir.mkdir(exist_ok=True)
    figures.height_histogram(initial.height, initial.area, final.height, final.area,
                             job.slicing.layer_height_mm,
                             fig_dir / "layer_height_histogram.png")
    figures.convergence(result.trace.o_align, result.trace.height_std, fig_dir / "convergence.png")
    figures.section_view(extraction.layers, fig_dir / "section.png")
    final_stats, initial_stats = final.stats(), initial.stats()

    report = {
        "layers": extraction.layers.layer_count,
        "iterations": int(result.iterations),
        "status": result.status_text,
        "planar": job.slicing.planar,
        "critical_regions": extraction.critical_report,
        "height_mm": final_stats.as_dict(),
        # Baseline: the scalar harmonic field with the region constraints (paper [42]).
        "height_std_initial_mm": initial_stats.std,
        "height_initial_mm": initial_stats.as_dict(),
        # layer area whose H the extrusion profile's table does not cover
        "height_outside_profile": {**heights.outside_profile(final, lo, hi),
                                   "profile_range_mm": [lo, hi]},
        # Where the iteration starts: the harmonic vector field of eq. 6 and its Poisson
        # solve, a much stronger start than the baseline; final vs start is the iteration's
        # own improvement.
        "height_std_start_mm": (
            result.height_start.std if result.height_start is not None else None
        ),
        "o_align": [float(x) for x in result.trace.o_align],
        "height_std_per_iteration_mm": [float(x) for x in result.trace.height_std],
        "layer_height_check": extraction.height_check,
        "height_slab_scale": _scale_summary(extraction.height_scale),
        # critical values inside the range made slab boundaries, and the slab thickness
        # relative to the target spacing that this leaves (1 everywhere without them)
        "slab_anchors": [float(a) for a in extraction.spacing.anchors],
        "slab_thickness_ratio": _thickness_ratio(extraction.spacing),
        # remarks for the user: critical selectors that matched nothing or left patches
        # out, reoriented tets, solver fallbacks (slicer.checks prints them)
        "notes": list(result.notes),
        "timing_s": dict(result.timings),
    }
    return report, extraction


def _toolpath(
    tetmesh: TetMesh, extraction: LayerExtraction, job: JobConfig, out_dir: Path,
    surface: Surface, progress: Progress | None, alpha: AlphaRange,
    accel: PathAccel | None = None,
) -> dict[str, Any]:
    """Toolpath generation, its files, pictures and report section. A part whose walls are
    too thin for the narrowest line is refused here (``ThinWallsError``, with the section
    so far) unless ``toolpath.thin_walls`` is "thicken"."""
    from slicer.extrusion import load_profile
    from slicer.toolpath.build import compute_toolpath
    from slicer.toolpath.coverage import layer_coverage
    from slicer.toolpath.directions import direction_report
    from slicer.toolpath.export import export_layers_txt
    from slicer.toolpath.figures import write_toolpath_figures

    profile = load_profile(job.extrusion.profile)
    layers = extraction.layers
    result = compute_toolpath(layers, job, profile, progress=progress,
                              measure_baselines=job.toolpath.measure_baselines, accel=accel)
    report = dict(result.report)
    model_volume = surface.volume_mm3
    _too_thin(result, report, job, surface, extraction.slab_mm3)
    toolpath = result.toolpath
    if job.toolpath.flush:
        from slicer.toolpath.flush import flush_toolpath

        # exposed filaments (first/last layers, treads under a slope) moved inwards so they
        # do not bulge out of the model; the deposited ink is unchanged
        toolpath, flushed = flush_toolpath(toolpath, tetmesh, profile, alpha=alpha)
        report["flush"] = flushed.as_dict()
    if job.toolpath.relieve_bends:
        from slicer.toolpath.relief import relieve_bends

        # no nozzle angle within the cell's alpha range follows a path that bends out of its
        # layer
        toolpath, relief = relieve_bends(toolpath, alpha)
        report["bend_relief"] = {**relief.as_dict(), "limit_deg": alpha.step_elevation_deg}
    toolpath.save(out_dir)
    profile.save_to_job(out_dir)  # the job's C, set-point and morphology: one owner, recorded
    # what the toolpath leaves bare or covers twice (connectors included), and the printing
    # directions the robot will have to follow
    start = time.perf_counter()
    report["coverage"] = layer_coverage(layers, toolpath).summary()
    report["coverage"]["seconds"] = round(time.perf_counter() - start, 3)
    report["printing_direction"] = direction_report(toolpath)
    export_layers_txt(toolpath, out_dir / "layers_txt")
    write_toolpath_figures(result, layers, out_dir / "figures")
    deposited = float(report["deposited_volume_mm3"])
    report["volume_error"] = deposited / model_volume - 1.0 if model_volume > 0 else float("nan")
    report["slab_volume"] = _slab_check(extraction.slab_mm3, report)
    return report


def _too_thin(result: ToolpathResult, report: dict[str, Any], job: JobConfig,
              surface: Surface, slab_mm3: np.ndarray) -> None:
    """Adds ``too_thin`` (``thin_features.ThinFeatures.summary``) to the toolpath ``report``
    and each marked layer's excess to its per-layer entry (extra ink within the layer's slab
    of the solid, ``slab_mm3`` (len(iso),) mm^3, not counted); raises ``ThinWallsError`` when
    that excess exceeds the limit and the job refuses, whatever the whole volume error (layers
    short of their slabs elsewhere can bring it within the limit while the walls still print
    wider than the model)."""
    from slicer.toolpath.thin_features import EXCESS_LIMIT, ThinFeatures, ThinWallsError

    thin = result.thin if result.thin is not None else ThinFeatures(
        np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros(0))
    volume = surface.volume_mm3
    slab = np.asarray(slab_mm3, dtype=np.float64)
    laid = np.zeros(len(slab))
    for entry in report.get("per_layer", []):
        if int(entry["layer"]) < len(slab):
            laid[int(entry["layer"])] = float(entry["deposited_mm3"])
    if len(slab) and len(thin.layer) and int(thin.layer.max()) < len(slab):
        thin = thin.within_slabs(laid, slab)
    section = thin.summary(volume, float(max(surface.bbox_mm)))
    report["too_thin"] = section
    excess = dict((k, e) for k, e in section["layers"])
    for entry in report.get("per_layer", []):
        if int(entry["layer"]) in excess:
            entry["too_thin_mm3"] = excess[int(entry["layer"])]
    error = float(report["deposited_volume_mm3"]) / volume - 1.0 if volume > 0 else 0.0
    if job.toolpath.thin_walls == "refuse" and section["excess_share"] > EXCESS_LIMIT:
        report["volume_error"] = error
        raise ThinWallsError(Path(surface.source).name, report, surface.bbox_mm)


def _scale_summary(scale: np.ndarray) -> dict[str, Any]:
    """What matching H to the slab volumes did (``layers.match_slab_heights``)."""
    from slicer.slabs import SCALE_LIMITS

    if not len(scale):
        return {}
    off = np.flatnonzero(np.abs(scale - 1.0) > 0.01)
    return {"min": float(scale.min()), "max": float(scale.max()),
            "layers_beyond_1pct": [[int(k), round(float(scale[k]), 4)] for k in off[:20]],
            "at_limit": int(np.sum((scale <= SCALE_LIMITS[0]) | (scale >= SCALE_LIMITS[1])))}


def _thickness_ratio(spacing: LayerSpacing) -> list[float]:
    """[min, max] slab thickness / requested spacing delta."""
    thickness = np.diff(spacing.bounds)
    if not len(thickness) or not np.isfinite(spacing.delta) or spacing.delta <= 0:
        return []
    return [float(thickness.min() / spacing.delta), float(thickness.max() / spacing.delta)]


def _slab_check(slab: np.ndarray, report: dict[str, Any]) -> dict[str, Any]:
    """Each layer's required volume (the integral of H over it, what the toolpath deposits)
    against the exact volume of its slab of the solid (``slab``, (len(iso),) mm^3, from the
    layers stage). They differ where the cross-section changes fast within a slab (a part
    ending or starting mid-slab): there the ink of the layer lands next to the solid, and the
    whole-model volume error carries the sum of those differences. The layers stage scales
    each layer's H to its slab (``layers.match_slab_heights``; the slicing report's
    ``height_slab_scale`` says by how much), so the two agree unless that factor hit its
    limit: a check, not a correction.
    Adds ``slab_mm3`` to each per-layer entry."""
    if len(slab) == 0:
        return {}
    layers = report.get("per_layer", [])
    required = np.zeros(len(slab))
    for entry in layers:
        k = int(entry["layer"])
        if 0 <= k < len(slab):
            required[k] = float(entry["required_mm3"])
            entry["slab_mm3"] = float(slab[k])
    rel = np.abs(required - slab) / np.maximum(slab, tol.floor)
    worst = int(np.argmax(np.abs(required - slab)))
    return {
        "slab_sum_mm3": float(slab.sum()),
        "required_sum_mm3": float(required.sum()),
        "layer_rel_error_p50": float(np.median(rel)),
        "layer_rel_error_p90": float(np.percentile(rel, 90)),
        "worst_layer": worst,
        "worst_layer_mm3": [float(required[worst]), float(slab[worst])],
    }


def _finish(out_dir: Path, report: dict[str, Any], timer: StageTimer, t0: float) -> dict[str, Any]:
    timing = {name: round(seconds, 3) for name, seconds in timer.seconds.items()}
    timing["total"] = round(time.perf_counter() - t0, 3)
    report["timing_s"] = timing
    report["peak_memory_mb"] = _peak_memory_mb()
    return update_report(out_dir, report)


def _peak_memory_mb() -> float:
    import resource

    return float(np.round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1))
