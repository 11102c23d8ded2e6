"""Import planar G-code from a commercial slicer (Cura, PrusaSlicer) as a Toolpath baseline.

Understood: G0/G1 linear moves (X Y Z E F; also modal bare coordinate lines), G2/G3 arcs in
the XY plane (I J, linearised), several G words on one line,
G20/G21 (inch/mm), G90/G91 (absolute/relative axes), M82/M83 (absolute/relative E),
G92 (set position, including E resets), comments after ';' and in parentheses.
Cura/PrusaSlicer ``;TYPE:`` comments mark walls (contour) and infill (stripe).

A move extrudes when E advances and the nozzle moves in XY. Consecutive extruding moves form
one path; a layer starts whenever the Z of an extruding move rises. Per waypoint:

* height = Z step to the previous printed layer (the first layer: its Z above the bed, z = 0);
* width = extruded volume per mm / height, the volume per E unit being the filament cross
  section (``filament_diameter_mm``) or 1 mm^3 in volumetric-E mode (diameter 0);
* speed: ``"volume"`` (default) sets v = C / (width * height) so the cell's constant-rate
  extruder deposits exactly the volume the G-code asks for; ``"feedrate"`` keeps F / 60.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from core.stages import MAX_COORDINATE_MM, Pattern, Toolpath
from core.tolerance import tol
from slicer.extrusion import factory_rate

MAX_GCODE_BYTES = 256 << 20  # a G-code file larger than this is refused before it is read

_WORD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)")
_CONTOUR_TYPES = ("WALL", "PERIMETER", "SKIRT", "BRIM", "EXTERNAL", "OVERHANG")


@dataclass(frozen=True)
class GcodeOptions:
    """How to read E and F.

    Attributes:
        filament_diameter_mm: float, mm; 0 means E is already a volume (mm^3).
        rate_mm3_s: float, mm^3/s, extrusion rate C of the cell (for speed "volume").
        speed: "volume" (v = C / (W H)) or "feedrate" (v = F / 60).
        arc_step_mm: float, mm, chord length used to linearise G2/G3 arcs.
    """

    filament_diameter_mm: float = 1.75
    rate_mm3_s: float = field(default_factory=factory_rate)  # the factory profile's C
    speed: Literal["volume", "feedrate"] = "volume"
    arc_step_mm: float = 0.5

    def __post_init__(self) -> None:
        if self.filament_diameter_mm < 0 or self.rate_mm3_s <= 0 or self.arc_step_mm <= 0:
            raise InputError("G-code options: negative filament diameter, rate or arc step",
                             "use filament_diameter_mm >= 0, rate and arc step > 0")
        if self.speed not in ("volume", "feedrate"):
            raise InputError(f"G-code speed mode '{self.speed}'", "use volume or feedrate")


def read_gcode(path: Path, options: GcodeOptions | None = None) -> Toolpath:
    """Parse a G-code file (see the module docstring).

    Raises:
        InputError: missing/unreadable file, or no extruding move in it.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"G-code file {path} does not exist", "check the --gcode path")
    if path.stat().st_size > MAX_GCODE_BYTES:
        raise InputError(f"G-code file {path} is larger than {MAX_GCODE_BYTES >> 20} MiB",
                         "give the G-code of one part")
    try:
        text = path.read_text(errors="replace")
    except OSError as exc:
        raise InputError(f"cannot read {path} ({exc})", "check the file permissions") from exc
    return parse_gcode(text, options, source=str(path))


def parse_gcode(text: str, options: GcodeOptions | None = None,
                source: str = "G-code") -> Toolpath:
    """Parse G-code text into a Toolpath of its extruding moves (travel moves dropped)."""
    opt = options or GcodeOptions()
    dia = opt.filament_diameter_mm
    e_scale = math.pi * 0.25 * dia**2 if dia > 0 else 1.0  # mm^3 per E unit
    pos = np.zeros(3)
    e = 0.0
    feed = 1500.0  # mm/min, a common firmware default until the file sets F
    unit = 1.0
    abs_xyz, abs_e = True, True
    kind = Pattern.STRIPE
    last_motion: float | None = None
    # One row per extruding move: start xyz, end xyz, volume, feed, pattern.
    rows: list[tuple[float, float, float, float, float, float, float, float, int]] = []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split(";", 1)
        comment = line[1].strip() if len(line) > 1 else ""
        if comment.upper().startswith("TYPE:"):
            label = comment[5:].strip().upper()
            kind = Pattern.CONTOUR if any(t in label for t in _CONTOUR_TYPES) else Pattern.STRIPE
        code = re.sub(r"\([^)]*\)", " ", line[0]).strip()
        if not code:
            continue
        tokens = [(k.upper(), float(v)) for k, v in _WORD.findall(code)]
        for k, v in tokens:
            if k in "XYZIJ" and not abs(v) * unit <= MAX_COORDINATE_MM:
                raise InputError(f"{source} line {number}: {k}{v:g} lies beyond "
                                 f"{MAX_COORDINATE_MM:g} mm", "export the G-code again in mm")
            if not math.isfinite(v):
                raise InputError(f"{source} line {number}: {k} is not a finite number",
                                 "export the G-code again")
        gs = [v for k, v in tokens if k == "G"]
        words = {k: v for k, v in tokens if k != "G"}
        for g in gs:
            if g in (20.0, 21.0):
                unit = 25.4 if g == 20.0 else 1.0
            elif g == 90.0:
                abs_xyz, abs_e = True, True
            elif g == 91.0:
                abs_xyz, abs_e = False, False
        if 92.0 in gs:
            for i, ax in enumerate("XYZ"):
                if ax in words:
                    pos[i] = words[ax] * unit
            if "E" in words:
                e = words["E"] * unit
            continue
        motion = next((g for g in gs if g in (0.0, 1.0, 2.0, 3.0)), None)
        if motion is None and not gs and "M" not in words and "T" not in words and any(
                ax in words for ax in "XYZE"):
            motion = last_motion  # modal: a bare coordinate line repeats the last move
        if motion is not None:
            last_motion = motion
            if "F" in words:
                feed = words["F"] * unit
            target = pos.copy()
            for i, ax in enumerate("XYZ"):
                if ax in words:
                    target[i] = words[ax] * unit + (0.0 if abs_xyz else pos[i])
            de = 0.0
            if "E" in words:
                new_e = words["E"] * unit + (0.0 if abs_e else e)
                de, e = new_e - e, new_e
            if motion in (2.0, 3.0):
                pts = _arc(pos, target, words.get("I", 0.0) * unit,
                           words.get("J", 0.0) * unit, motion == 2.0, opt.arc_step_mm)
            else:
                pts = np.stack([pos, target])
            seg = np.linalg.norm(np.diff(pts[:, :2], axis=0), axis=1)
            if de > 0 and seg.sum() > 0:
                vol = de * e_scale * seg / seg.sum()
                for a, b, v in zip(pts[:-1], pts[1:], vol, strict=True):
                    rows.append((*a, *b, float(v), feed, kind))
            pos = target
        if "M" in words:
            if words["M"] == 82.0:
                abs_e = True
            elif words["M"] == 83.0:
                abs_e = False
    if not rows:
        raise InputError(f"{source} has no extruding move", "export G-code with E values")
    with np.errstate(all="ignore"):  # a degenerate move shows in the check below
        toolpath = _to_toolpath(np.array(rows, dtype=np.float64), opt)
    values = np.concatenate([toolpath.height, toolpath.width, toolpath.speed])
    problem = ("a move has a NaN or infinite height, width or speed"
               if not np.all(np.isfinite(values)) else toolpath.check())
    if problem:
        raise InputError(f"{source}: {problem}",
                         "export the G-code again with the extrusion (E) and feed (F) it prints")
    return toolpath


def _arc(start: NDArray[np.float64], end: NDArray[np.float64], i: float, j: float,
         clockwise: bool, step: float) -> NDArray[np.float64]:
    """(n, 3) points of a G2/G3 arc from ``start`` to ``end`` around start + (I, J)."""
    c = start[:2] + np.array([i, j])
    r = float(np.linalg.norm(start[:2] - c))
    a0 = math.atan2(start[1] - c[1], start[0] - c[0])
    a1 = math.atan2(end[1] - c[1], end[0] - c[0])
    sweep = a1 - a0
    if clockwise and sweep >= 0:
        sweep -= 2 * math.pi
    elif not clockwise and sweep <= 0:
        sweep += 2 * math.pi
    n = max(2, math.ceil(abs(sweep) * max(r, tol.floor) / step) + 1)
    a = a0 + np.linspace(0.0, sweep, n)
    pts = np.column_stack([c[0] + r * np.cos(a), c[1] + r * np.sin(a),
                           np.linspace(start[2], end[2], n)])
    pts[-1] = end
    return pts


def _to_toolpath(rows: NDArray[np.float64], opt: GcodeOptions) -> Toolpath:
    start, end = rows[:, 0:3], rows[:, 3:6]
    vol, feed, kind = rows[:, 6], rows[:, 7], rows[:, 8].astype(np.int8)
    length = np.linalg.norm(end - start, axis=1)
    # A new path wherever a move does not start where the previous one ended.
    brk = np.r_[True, np.linalg.norm(start[1:] - end[:-1], axis=1) > tol.still]
    path_of_move = np.cumsum(brk) - 1
    # Layers: Z levels of extruding moves, new layer whenever Z rises.
    z = end[:, 2]
    layer_z = np.unique(np.round(z, 4))
    layer_of_move = np.searchsorted(layer_z, np.round(z, 4))
    heights = np.diff(np.r_[0.0, layer_z])
    height = heights[layer_of_move]
    height = np.where(height > 0, height, np.median(heights[heights > 0]) if np.any(heights > 0)
                      else 0.2)
    width = vol / np.maximum(length * height, tol.zero)
    if opt.speed == "volume":
        speed = opt.rate_mm3_s / np.maximum(width * height, tol.zero)
    else:
        speed = feed / 60.0
    # Waypoints: each path's first start point, then every move's end point.
    first = np.flatnonzero(brk)
    n_moves = len(rows)
    n = n_moves + len(first)
    out_idx = np.arange(n_moves) + np.searchsorted(first, np.arange(n_moves), side="right")
    start_idx = first + np.arange(len(first))
    position = np.empty((n, 3))
    position[out_idx] = end
    position[start_idx] = start[first]

    def spread(values: NDArray[np.float64] | NDArray[np.int64] | NDArray[np.int8]
               ) -> NDArray[np.float64]:
        out = np.empty(n, dtype=np.float64)
        out[out_idx] = values
        out[start_idx] = values[first]
        return out

    return Toolpath(
        position=position,
        normal=np.tile([0.0, 0.0, 1.0], (n, 1)),
        layer=spread(layer_of_move).astype(np.int32),
        path=spread(path_of_move).astype(np.int32),
        height=spread(height),
        width=spread(width),
        speed=spread(speed),
        extrude=np.ones(n, dtype=bool),
        pattern=spread(kind).astype(np.int8),
    )


def align_to_bounds(toolpath: Toolpath, bounds: NDArray[np.float64],
                    slab_middle: bool = False) -> Toolpath:
    """Shift a bed-frame toolpath onto a model: centre in x, y; first layer's bottom on z min.

    A G-code Z is the nozzle height, the top of its layer (the slicer cut that layer's
    section at Z - H / 2). ``sim.deposition`` centres each filament on the nozzle tip, the
    convention of the curved toolpath and of ``sim.baseline`` (waypoints on the middle of their
    slab). With ``slab_middle`` the print is lowered by half the first layer's height more, so
    every layer is deposited around the plane its section was cut at, as in an embedded print
    (no bed: the whole print may float H / 2 lower). Without it (the default) the layer tops
    stay where a bed printer puts them.

    Args:
        toolpath: e.g. from ``read_gcode`` (coordinates of the printer bed).
        bounds: (2, 3) float64, mm, the model's min and max corners.
        slab_middle: put the waypoints on the middle of their layer slab (see above).
    """
    b = np.asarray(bounds, dtype=np.float64)
    p = toolpath.position
    shift = np.zeros(3)
    shift[:2] = 0.5 * (b[0, :2] + b[1, :2]) - 0.5 * (p[:, :2].min(axis=0) + p[:, :2].max(axis=0))
    first = toolpath.layer == toolpath.layer.min()
    bottom = float((p[first, 2] - toolpath.height[first]).min())
    shift[2] = b[0, 2] - bottom
    if slab_middle:
        shift[2] -= 0.5 * float(np.median(toolpath.height[first]))
    arrays = toolpath.arrays()
    arrays["position"] = p + shift
    return Toolpath(**arrays)
