"""A commercial planar slicer as a baseline: PrusaSlicer's CLI on the job's model.

``mesp inspect DIR --baseline prusaslicer`` slices the job's model with PrusaSlicer (a Debian
package, ``make baselines`` installs it), imports the G-code through ``sim.gcode.read_gcode``
and prints it through the same deposition model as the multi-axis toolpath. The settings are
the ones an embedded-printing user would type into a commercial slicer (paper sections 2.1,
3.1, 3.2): planar layers of one height H, lines of one width W at a fixed overlap ratio beta
(H = beta h_f, W = beta w_f), one constant speed, solid infill, no skirt, brim or support.

Mapping from the calibration profile (``slicer/profiles/*.toml`` through
``slicer.extrusion.ExtrusionProfile``, or any ``sim.deposition.Morphology``) to PrusaSlicer:

========================  ====================================================================
PrusaSlicer option        value
========================  ====================================================================
layer_height,             H (``PrusaConfig.layer_height_mm``; ``mesp inspect`` passes the median
first_layer_height        toolpath height, like the planar baseline)
all print speeds          v = f(H / beta): the profile's speed whose filament height is
                          h_f = H / beta (``sim.baseline.speed_for_height``); perimeters, infill,
                          first layer, gap fill, bridges and travel all run at v
(line spacing)            W = beta w_f(v), the overlap rule of paper section 3.2
extrusion_width (all      W + H (1 - pi / 4): PrusaSlicer models a line as a rectangle with
kinds of line)            round ends, so its neighbouring lines lie at width - H (1 - pi / 4)
                          and it extrudes H x spacing per mm; this makes the spacing W and the
                          ink per mm W H
extrusion_multiplier      pi / (4 beta^2): the ink per mm is then the filament's own section
                          A_f = pi/4 w_f h_f = C / v, so the G-code's volume rate at feed v is
                          the cell's constant rate C (1.0 at the volume-matching beta
                          sqrt(pi)/2 = 0.886, the default, where lines tile their layer;
                          PrusaSlicer caps it at 2, so beta >= sqrt(pi / 8) = 0.627)
nozzle_diameter           extrusion_width (PrusaSlicer only uses it to validate widths and
                          heights; the needle's bore does not enter the G-code)
use_volumetric_e          on: E is in mm^3, read with ``GcodeOptions(filament_diameter_mm=0)``
                          (off: filament_diameter 1.75 mm, read with the same diameter)
perimeters                1 (``PrusaConfig.perimeters``)
fill_density,             100 %, rectilinear everywhere (top, bottom, internal): lines turn by
fill_pattern              90 deg from layer to layer, the staggered pattern of paper Fig. 3(d)
infill_overlap            25 %, PrusaSlicer's default (``PrusaConfig.infill_overlap_pct``)
skirts, brim_width,       0, 0, off, off: the gel holds the part; ``thick_bridges`` and
support_material,         ``overhangs`` off, since nothing in a gel bath is a bridge
thick_bridges, overhangs
cooling, retraction       off, 0: a constant-rate extruder neither slows down nor retracts
bed_shape, center         a square bed around the model with the model centred on it;
                          ``sim.gcode.align_to_bounds(..., slab_middle=True)`` then puts the
                          print back on the model, each layer's filaments centred on the plane
                          PrusaSlicer cut its section at (Z - H / 2), the convention of
                          ``sim.deposition`` and of the other toolpaths
========================  ====================================================================

The model sliced is the job's ``model.ply``: the surface ``mesp slice`` read from the file
named in ``report.json`` ``job.model_file``, already in mm and in the model frame (so unit
conversions and tet-mesh inputs need nothing here), written out as STL. The G-code is read as
``sim.gcode`` reads any G-code (speed "volume": the cell times each move so its constant rate
lays down the G-code's E). The G-code is written into the job directory
(``baseline_prusaslicer.gcode``, next to the STL it was sliced from,
``baseline_prusaslicer.stl``) so it can be looked at. PrusaSlicer runs with
a private, empty ``--datadir`` so a user's own PrusaSlicer presets never leak into the
baseline. A missing executable, a PrusaSlicer error (its last stderr line) and a timeout all
raise ``core.errors.InputError``.
"""

from __future__ import annotations

import math
import re
import shutil
import subprocess
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.artifacts import atomic_write_bytes
from core.errors import InputError
from core.stages import Toolpath
from sim.baseline import VOLUME_MATCHING_BETA, speed_for_height
from sim.deposition import Morphology
from sim.gcode import GcodeOptions, align_to_bounds, read_gcode

DEFAULT_EXECUTABLE = "prusa-slicer"
GCODE_FILE = "baseline_prusaslicer.gcode"
STL_FILE = "baseline_prusaslicer.stl"
INSTALL_FIX = "install it: make baselines (or apt-get install prusa-slicer)"
FILAMENT_DIAMETER_MM = 1.75  # used only when volumetric E is off
# PrusaSlicer's flow model: spacing = width - H (1 - pi/4) between lines of one kind.
ROUND_END_LOSS = 1.0 - math.pi / 4.0
# PrusaSlicer refuses extrusion multipliers above 2, so pi / (4 beta^2) <= 2 needs this beta.
MIN_BETA = math.sqrt(math.pi / 8.0)


@dataclass(frozen=True)
class PrusaConfig:
    """What the user chooses for the PrusaSlicer baseline.

    Attributes:
        layer_height_mm: float, mm, constant layer height H.
        beta: float, overlap ratio, H = beta h_f and W = beta w_f (default sqrt(pi)/2, where
            W H equals the filament section and lines tile their layer; at least
            ``MIN_BETA`` = 0.627, see the module docstring).
        perimeters: int, perimeter loops per layer.
        infill_overlap_pct: float, %, infill reaching into the perimeter (PrusaSlicer's 25).
        volumetric_e: bool, E in mm^3 (True) or in mm of 1.75 mm filament (False).
        timeout_s: float, s, PrusaSlicer is stopped and an InputError raised after this.
        bed_margin_mm: float, mm, free bed around the model.
        executable: str | None, the PrusaSlicer command; None = ``DEFAULT_EXECUTABLE``.
    """

    layer_height_mm: float = 0.6
    beta: float = VOLUME_MATCHING_BETA
    perimeters: int = 1
    infill_overlap_pct: float = 25.0
    volumetric_e: bool = True
    timeout_s: float = 600.0
    bed_margin_mm: float = 20.0
    executable: str | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.layer_height_mm) and 0.02 <= self.layer_height_mm <= 20.0):
            raise InputError(f"PrusaSlicer layer height {self.layer_height_mm} mm",
                             "use 0.02 to 20 mm")
        if not (math.isfinite(self.beta) and MIN_BETA <= self.beta <= 1.0):
            raise InputError(f"PrusaSlicer overlap beta {self.beta:g} needs an extrusion "
                             f"multiplier pi / (4 beta^2) above PrusaSlicer's limit of 2",
                             f"use a beta from {MIN_BETA:.3f} to 1")
        if not 0 <= self.perimeters <= 20:
            raise InputError(f"PrusaSlicer perimeters {self.perimeters}", "use 0 to 20")
        if not 0.0 <= self.infill_overlap_pct <= 100.0:
            raise InputError(f"PrusaSlicer infill overlap {self.infill_overlap_pct} %",
                             "use 0 to 100 %")
        if not (self.timeout_s > 0 and self.bed_margin_mm >= 0):
            raise InputError("PrusaSlicer timeout must be positive and bed margin >= 0",
                             "fix the baseline settings")


@dataclass(frozen=True)
class PrusaSettings:
    """The PrusaSlicer settings derived from a profile and a ``PrusaConfig`` (mm, mm/s).

    Attributes:
        layer_height_mm: H.
        beta: overlap ratio.
        speed_mm_s: v = f(H / beta), every print move.
        filament_width_mm, filament_height_mm: w_f, h_f of the filament at v.
        line_spacing_mm: W = beta w_f, distance between neighbouring lines.
        extrusion_width_mm: W + H (1 - pi/4), PrusaSlicer's extrusion width.
        extrusion_multiplier: pi / (4 beta^2).
        nozzle_diameter_mm: PrusaSlicer's nozzle diameter (= extrusion width).
        perimeters, infill_overlap_pct, volumetric_e: from the config.
        bed_size_mm: side of the square bed; the model is centred on it.
        max_print_height_mm: the bed's height limit, above the model.
    """

    layer_height_mm: float
    beta: float
    speed_mm_s: float
    filament_width_mm: float
    filament_height_mm: float
    line_spacing_mm: float
    extrusion_width_mm: float
    extrusion_multiplier: float
    nozzle_diameter_mm: float
    perimeters: int
    infill_overlap_pct: float
    volumetric_e: bool
    bed_size_mm: float
    max_print_height_mm: float

    def options(self) -> list[str]:
        """PrusaSlicer command-line options (everything but input, output and datadir)."""
        h, v, w = self.layer_height_mm, self.speed_mm_s, self.extrusion_width_mm
        bed, c = self.bed_size_mm, 0.5 * self.bed_size_mm
        opts = [
            "--layer-height", _num(h), "--first-layer-height", _num(h),
            "--nozzle-diameter", _num(self.nozzle_diameter_mm),
            "--extrusion-multiplier", _num(self.extrusion_multiplier),
            "--perimeters", str(self.perimeters),
            "--fill-density", "100%", "--fill-pattern", "rectilinear",
            "--top-fill-pattern", "rectilinear", "--bottom-fill-pattern", "rectilinear",
            "--infill-overlap", f"{_num(self.infill_overlap_pct)}%",
            "--skirts", "0", "--brim-width", "0", "--no-support-material",
            "--no-thick-bridges", "--no-overhangs",
            "--no-cooling", "--slowdown-below-layer-time", "0",
            "--retract-length", "0", "--retract-lift", "0", "--no-wipe",
            "--start-gcode", "", "--end-gcode", "",
            "--bed-shape", f"0x0,{_num(bed)}x0,{_num(bed)}x{_num(bed)},0x{_num(bed)}",
            "--center", f"{_num(c)},{_num(c)}",
            "--max-print-height", _num(self.max_print_height_mm),
        ]
        for kind in ("", "first-layer-", "perimeter-", "external-perimeter-", "infill-",
                     "solid-infill-", "top-infill-"):
            opts += [f"--{kind}extrusion-width", _num(w)]
        for kind in ("perimeter", "external-perimeter", "small-perimeter", "infill",
                     "solid-infill", "top-solid-infill", "first-layer", "gap-fill", "bridge",
                     "travel"):
            opts += [f"--{kind}-speed", _num(v)]
        if self.volumetric_e:
            opts.append("--use-volumetric-e")
        else:
            opts += ["--filament-diameter", _num(FILAMENT_DIAMETER_MM)]
        return opts

    def gcode_options(self, rate_mm3_s: float) -> GcodeOptions:
        """How ``sim.gcode`` must read this G-code's E (volumetric or 1.75 mm filament)."""
        return GcodeOptions(filament_diameter_mm=0.0 if self.volumetric_e
                            else FILAMENT_DIAMETER_MM, rate_mm3_s=rate_mm3_s)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready settings, mm, mm/s, %."""
        return {k: (round(v, 6) if isinstance(v, float) else v) for k, v in asdict(self).items()}


@dataclass(frozen=True)
class CommercialResult:
    """A PrusaSlicer baseline print.

    Attributes:
        toolpath: the imported G-code moved onto the model (``align_to_bounds``, waypoints
            on the middle of their layer slab).
        gcode_path: the G-code file PrusaSlicer wrote.
        stl_path: the STL it sliced.
        version: PrusaSlicer's version, from the G-code header ("unknown" if absent).
        settings: the settings used.
        seconds: float, s, PrusaSlicer's run time.
    """

    toolpath: Toolpath
    gcode_path: Path
    stl_path: Path
    version: str
    settings: PrusaSettings
    seconds: float

    def info(self) -> dict[str, Any]:
        """The report.json description of the baseline (without its simulated quality)."""
        return {"kind": "prusaslicer", "slicer": "PrusaSlicer", "version": self.version,
                "gcode": self.gcode_path.name, "model": self.stl_path.name,
                "settings": self.settings.as_dict(), "slicer_seconds": round(self.seconds, 3)}


def find_prusaslicer(executable: str | None = None) -> str:
    """The absolute path of the PrusaSlicer executable.

    Raises:
        InputError: it is not installed (not on PATH / not a file).
    """
    name = executable or DEFAULT_EXECUTABLE
    found = shutil.which(name)
    if found is None:
        raise InputError(f"PrusaSlicer ('{name}') is not installed", INSTALL_FIX)
    return found


def prusa_settings(morphology: Morphology, config: PrusaConfig,
                   bounds: NDArray[np.float64]) -> PrusaSettings:
    """Derive PrusaSlicer's settings from the extrusion profile (see the module docstring).

    Args:
        morphology: the extrusion profile (rate C and filament size at a speed).
        config: the user's choices.
        bounds: (2, 3) float64, mm, the model's min and max corners (bed size).
    """
    h, beta = config.layer_height_mm, config.beta
    v = speed_for_height(morphology, h / beta)
    w_f, h_f = (float(np.asarray(a, dtype=np.float64).ravel()[0])
                for a in morphology.filament_size(np.array([v])))
    spacing = beta * w_f
    width = spacing + h * ROUND_END_LOSS
    extent = np.ptp(np.asarray(bounds, dtype=np.float64), axis=0)
    return PrusaSettings(
        layer_height_mm=h, beta=beta, speed_mm_s=v, filament_width_mm=w_f,
        filament_height_mm=h_f, line_spacing_mm=spacing, extrusion_width_mm=width,
        extrusion_multiplier=math.pi / (4.0 * beta * beta),
        # PrusaSlicer rejects layers taller than the nozzle and lines far wider than it.
        nozzle_diameter_mm=max(width, h),
        perimeters=config.perimeters, infill_overlap_pct=config.infill_overlap_pct,
        volumetric_e=config.volumetric_e,
        bed_size_mm=float(np.ceil(max(extent[0], extent[1]) + 2 * config.bed_margin_mm)),
        max_print_height_mm=float(np.ceil(extent[2] + config.bed_margin_mm)),
    )


def run_prusaslicer(stl: Path, gcode: Path, settings: PrusaSettings,
                    config: PrusaConfig) -> tuple[str, float]:
    """Slice ``stl`` into ``gcode`` with PrusaSlicer; returns (version, seconds).

    Raises:
        InputError: PrusaSlicer missing, failing (its last stderr line), silent (no G-code)
            or slower than ``config.timeout_s``.
    """
    exe = find_prusaslicer(config.executable)
    gcode.unlink(missing_ok=True)
    with tempfile.TemporaryDirectory(prefix="mesp-prusaslicer-") as datadir:
        cmd = [exe, "--export-gcode", str(stl), "--datadir", datadir, "--loglevel", "1",
               *settings.options(), "--output", str(gcode)]
        t0 = time.perf_counter()
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, errors="replace",
                                  timeout=config.timeout_s, check=False)
        except subprocess.TimeoutExpired as exc:
            raise InputError(f"PrusaSlicer did not finish within {config.timeout_s:g} s",
                             "simplify the model or use a larger layer height") from exc
        except OSError as exc:
            raise InputError(f"cannot run PrusaSlicer {exe} ({exc.strerror})",
                             INSTALL_FIX) from exc
        seconds = time.perf_counter() - t0
    if proc.returncode != 0 or not gcode.is_file() or gcode.stat().st_size == 0:
        raise InputError(f"PrusaSlicer failed on {stl.name} (exit {proc.returncode}): "
                         f"{_last_line(proc.stderr) or _last_line(proc.stdout) or 'no output'}",
                         "check the model and the baseline settings (--baseline-height, "
                         "--baseline-beta)")
    return _version(gcode), seconds


def slice_with_prusaslicer(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                           morphology: Morphology, config: PrusaConfig,
                           out_dir: Path) -> CommercialResult:
    """Slice a closed mesh with PrusaSlicer and import the print as a Toolpath on the mesh.

    Args:
        vertices: (V, 3) float64, mm, the model (the job's ``model.ply``).
        faces: (F, 3) int, its triangles.
        morphology: extrusion profile (rate C, filament size at a speed).
        config: baseline settings.
        out_dir: where ``baseline_prusaslicer.stl`` and ``.gcode`` are written (the job dir).

    Raises:
        InputError: see ``run_prusaslicer``; also a G-code without extruding moves.
    """
    import trimesh

    v = np.asarray(vertices, dtype=np.float64)
    bounds = np.stack([v.min(axis=0), v.max(axis=0)])
    settings = prusa_settings(morphology, config, bounds)
    find_prusaslicer(config.executable)  # fail before writing anything
    out_dir = Path(out_dir)
    stl, gcode = out_dir / STL_FILE, out_dir / GCODE_FILE
    data = trimesh.Trimesh(v, np.asarray(faces), process=False).export(file_type="stl")
    atomic_write_bytes(stl, data if isinstance(data, bytes) else str(data).encode())
    version, seconds = run_prusaslicer(stl, gcode, settings, config)
    printed = read_gcode(gcode, settings.gcode_options(float(morphology.rate_mm3_s)))
    return CommercialResult(toolpath=align_to_bounds(printed, bounds, slab_middle=True),
                            gcode_path=gcode, stl_path=stl, version=version,
                            settings=settings, seconds=seconds)


def _num(x: float) -> str:
    """A number as PrusaSlicer reads it (plain decimal, no exponent)."""
    return f"{x:.6f}".rstrip("0").rstrip(".")


def _last_line(text: str) -> str:
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return lines[-1] if lines else ""


def _version(gcode: Path) -> str:
    """PrusaSlicer's version from the header line '; generated by PrusaSlicer X.Y.Z ...'."""
    with gcode.open(errors="replace") as fh:
        for _, line in zip(range(20), fh, strict=False):
            m = re.search(r"generated by PrusaSlicer\s+(\S+)", line)
            if m:
                return m.group(1)
    return "unknown"
