"""The toolpaths a job's virtual print is compared with: a planar slicer, PrusaSlicer, G-code.

Each returns the baseline as a ``Toolpath`` on the job's model and a JSON-ready description
for the report. The planar baseline comes in two width rules (overlap W = beta w_f and
volume-preserving W = C / (H v), ``sim.baseline``); the volume rule shares the curved
toolpath's filament rules, so it is flushed like a curved job where the job has tets.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from core.report import read_report
from core.stages import TetMesh, Toolpath
from sim.baseline import VOLUME_MATCHING_BETA, PlanarConfig, planar_toolpath
from sim.commercial import PrusaConfig, find_prusaslicer, slice_with_prusaslicer
from sim.gcode import GcodeOptions, align_to_bounds, read_gcode
from slicer.extrusion import ExtrusionProfile
from slicer.toolpath.flush import flush_toolpath


@dataclass(frozen=True)
class BaselineOptions:
    """Which baseline to print beside the job, and how.

    Attributes:
        kind: "planar" (``sim.baseline``), "prusaslicer" (``sim.commercial``) or None.
        gcode: a planar G-code file to print instead (Cura/PrusaSlicer), or None.
        height_mm: planar layer height, mm (None: the median of the job's extruding waypoints).
        beta: overlap ratio (None: sqrt(pi)/2 in overlap mode and for PrusaSlicer, the
            profile's beta in volume mode).
        width: the planar width rule: "overlap", "volume" or "both" (keep the better).
        filament_mm: filament diameter the G-code's E refers to, mm (0: E is a volume).
    """

    kind: Literal["planar", "prusaslicer"] | None = None
    gcode: Path | None = None
    height_mm: float | None = None
    beta: float | None = None
    width: Literal["overlap", "volume", "both"] = "both"
    filament_mm: float = 1.75


def check_prusaslicer(options: BaselineOptions) -> None:
    """Before minutes of simulation, not after: PrusaSlicer is installed and beta is in its
    range (one-line InputErrors)."""
    find_prusaslicer()
    PrusaConfig(beta=options.beta or VOLUME_MATCHING_BETA)


def flushed(job: Path, toolpath: Toolpath, morphology: ExtrusionProfile
            ) -> tuple[Toolpath, dict[str, Any]]:
    """The toolpath with exposed filaments made flush (slicer.toolpath.flush) and its report."""
    out, report = flush_toolpath(toolpath, TetMesh.load(job), morphology)
    return out, report.as_dict()


def gcode_print(options: BaselineOptions, morphology: ExtrusionProfile, vertices: np.ndarray
                ) -> tuple[Toolpath, dict[str, Any]]:
    """The G-code file's print, each layer around its cut plane on the model's bounds."""
    assert options.gcode is not None
    opts = GcodeOptions(filament_diameter_mm=options.filament_mm,
                        rate_mm3_s=float(morphology.rate_mm3_s))
    tp = read_gcode(options.gcode, opts)
    bounds = np.stack([vertices.min(axis=0), vertices.max(axis=0)])
    # Filaments centred on the nozzle tip (sim.deposition): each layer around its cut plane.
    return align_to_bounds(tp, bounds, slab_middle=True), {"kind": "gcode",
                                                           "file": str(options.gcode)}


def baseline_height(options: BaselineOptions, toolpath: Toolpath) -> float:
    """The planar layer height, else the median layer height of the job's extruding
    waypoints (mm)."""
    ext = toolpath.extrude
    return float(options.height_mm or (np.median(toolpath.height[ext]) if ext.any()
                                       else 0.6))


def prusa_print(options: BaselineOptions, job: Path, toolpath: Toolpath,
                morphology: ExtrusionProfile, vertices: np.ndarray, faces: np.ndarray
                ) -> tuple[Toolpath, dict[str, Any]]:
    """PrusaSlicer's print of the job's model (sim.commercial), moved onto the model."""
    cfg = PrusaConfig(layer_height_mm=baseline_height(options, toolpath),
                      beta=options.beta or VOLUME_MATCHING_BETA)
    result = slice_with_prusaslicer(vertices, faces, morphology, cfg, job)
    info = result.info()
    # model.ply is the job's model as mesp slice read it (mm, model frame); name its source.
    source = read_report(job).get("job", {}).get("model_file")
    info["model_source"] = f"model.ply (from {source})" if source else "model.ply"
    return result.toolpath, info


def planar_print(options: BaselineOptions, job: Path, mode: Literal["overlap", "volume"],
                 toolpath: Toolpath, morphology: ExtrusionProfile, vertices: np.ndarray,
                 faces: np.ndarray) -> tuple[Toolpath, dict[str, Any]]:
    """Planar baseline in one width mode, flushed like a curved job when the tets are there."""
    height = baseline_height(options, toolpath)
    default_beta = VOLUME_MATCHING_BETA if mode == "overlap" else float(
        getattr(morphology, "beta", VOLUME_MATCHING_BETA))
    beta = options.beta or default_beta
    cfg = PlanarConfig(layer_height_mm=height, beta=beta, width_mode=mode)
    tp = planar_toolpath(vertices, faces, morphology, cfg)
    info: dict[str, Any] = {"kind": "planar", "width_mode": mode,
                            "layer_height_mm": float(tp.height[0]), "beta": beta,
                            "width_mm": float(tp.width[0]), "speed_mm_s": float(tp.speed[0])}
    # The volume mode shares the curved toolpath's rules (h_f = H / beta, 2 H at beta 0.5), so
    # it gets the same flush. The overlap mode's filament barely exceeds H and is left as a
    # commercial slicer makes it (flushing it measured slightly worse).
    if mode == "volume" and (job / "tetmesh.npz").is_file():
        tp, info["flush"] = flushed(job, tp, morphology)
    return tp, info
