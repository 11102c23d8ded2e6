"""Virtual print: ink deposited by a toolpath into the support gel, on a voxel grid.

Model (paper sections 3.1, 3.2):

* The extruder pushes ink at a constant volumetric rate C (mm^3/s). A move of length L at
  nozzle speed v lasts dt = L / v and deposits C * dt; the filament cross-section has area
  A = C / v and is an ellipse w_f x h_f given by the calibrated morphology (``filament_size``),
  rescaled if needed so that pi/4 * w_f * h_f == C / v exactly.
* The ellipse is centred on the nozzle tip, its h_f axis along the printing direction (the
  waypoint ``normal``, projected perpendicular to the motion) and its w_f axis across the motion.
  Each extruding segment sweeps it along the segment (flat ends, so consecutive collinear
  segments tile without overlap). Why centred: the ink leaves the orifice at the tip into gel
  the needle has just yielded; the needle body above the tip pushes the ink down, the
  unyielded gel below the tip pushes it up, and the paper's layer rule H = beta h_f (section
  3.2) is the symmetric overlap of a filament with the layers above and below it. Neither
  side is measured for this profile, so ``DepositionConfig.center_offset`` shifts the centre
  along the printing direction (a fraction of h_f) for sensitivity studies. The consequence
  of a centred filament 2 H tall (beta = 0.5) on a layer that is the mid-surface of its slab:
  it sticks out (h_f - H) / 2 wherever nothing covers it (first layer, top layers, exposed
  treads); ``slicer.toolpath.flush`` moves those waypoints inwards.
* Silicone and gel do not mix: a voxel holds an ink fraction f in [0, 1], the rest is gel. Each
  segment's volume is shared over the voxels its swept ellipse covers, in proportion to the
  covered part of each voxel (exact along the segment, first-order signed distance across the
  ellipse), so the deposit resolves the filament boundary below the voxel size.
  Neighbouring filaments fuse only where they overlap; where they merely touch, the gel between
  them stays (pores).
* Ink landing in voxels that are already full (f > 1 after adding it) cannot compress: it is
  displaced into nearby free space (see ``sim.deposition_kernels.spread``). The connected
  over-full regions (where a new filament overlaps older ink) push their excess into the
  nearest voxels with room, nearest first; gaps and grooves of the ink (free voxels a
  morphological closing of the ink bridges, up to ``gap_mm`` wide) are wetted first, since
  the immiscible ink lowers its interface with the gel that way, and only then open gel.
  This is what makes a volume-matched toolpath fill the gaps between filaments: the
  over-height of each filament (h_f = H / beta) overlaps the layer below and is displaced
  into the gaps beside it; it is also why stacked (non-staggered) rasters keep aligned voids
  and why the first layer, which has nothing below to overlap, keeps its gaps (paper
  figure 3).
* Not modelled: the printing angle's effect on w_f, h_f (alpha is kept near 90 deg by the
  planner), gel flow, curing shrinkage, nozzle drag.

The toolpath is processed in print order in chunks (a layer, split into at most
``chunk_segments`` segments): a chunk's ink is rasterised at once, then its excess is spread.
Both are compiled kernels (``sim.deposition_kernels``, numba) that visit only the voxels near
the layer: a curved layer is a thin sheet in a large box. A worker thread rasterises the next
chunk while one spreads. A segment deposits when its two waypoints belong to the same path
and both extrude; its speed is the mean of theirs. Volume is conserved exactly up to float32
rounding of the fill field.
"""

from __future__ import annotations

import itertools
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from core.progress import NullProgress, Progress
from core.stages import Toolpath
from core.status import DepositionStatus
from core.tolerance import tol
from sim import deposition_kernels as kernels
from sim.voxels import MAX_VOXELS, VoxelGrid
from slicer.extrusion import factory_rate

# A voxel counts as full above this fill fraction; excess below it is float noise.
FULL = 1.0 - 1e-5
# A voxel is over-full (must shed ink) above this; the margin absorbs float32 rounding.
OVERFULL = 1.0 + 1e-5


class Morphology(Protocol):
    """What deposition needs from an extrusion profile (``slicer.extrusion.ExtrusionProfile``)."""

    @property
    def rate_mm3_s(self) -> float:
        """mm^3/s, constant extrusion rate C."""
        ...

    def filament_size(self, v: NDArray[np.float64]) -> tuple[NDArray[np.float64],
                                                              NDArray[np.float64]]:
        """Filament width w_f and height h_f (mm) at nozzle speed ``v`` (mm/s)."""
        ...


@dataclass(frozen=True)
class EllipseMorphology:
    """A simple morphology with a constant aspect ratio (tests, benchmarks, no calibration).

    Attributes:
        rate_mm3_s: float, mm^3/s, extrusion rate C.
        beta: float, overlap ratio H = beta * h_f (paper eq. 4).
        aspect: float, h_f / w_f.
    """

    rate_mm3_s: float = field(default_factory=factory_rate)  # the factory profile's C
    beta: float = 0.5
    aspect: float = 1.0

    def __post_init__(self) -> None:
        if self.rate_mm3_s <= 0 or not 0 < self.beta <= 1 or self.aspect <= 0:
            raise ValueError("need rate_mm3_s > 0, 0 < beta <= 1, aspect > 0")

    def filament_size(self, v: NDArray[np.float64]) -> tuple[NDArray[np.float64],
                                                              NDArray[np.float64]]:
        area = self.rate_mm3_s / np.asarray(v, dtype=np.float64)
        w = np.sqrt(4.0 * area / (np.pi * self.aspect))
        return w, self.aspect * w

    def speed_for_height(self, h_f: float) -> float:
        """mm/s, the speed at which the filament height is ``h_f`` mm."""
        w = h_f / self.aspect
        return float(self.rate_mm3_s / (0.25 * np.pi * w * h_f))


@dataclass(frozen=True)
class DepositionConfig:
    """Settings of the deposition simulation.

    Attributes:
        voxel_mm: float, mm, voxel edge.
        pad_mm: float, mm, free margin around the job in an automatic grid.
        spread_margin_mm: float, mm, how far from an over-full voxel its excess ink may be
            pushed in the first attempt (the neighbourhood searched for voxels with room; it
            doubles while a neighbourhood is full, up to 64 voxels: excess with no room
            within that is left over-full and the deposit's status is "overfull").
        max_passes: int, nearest-free-voxel passes per chunk and neighbourhood.
        chunk_segments: int, at most this many segments are rasterised before spreading.
        gap_mm: float, mm, excess goes first into gaps and grooves of the ink up to about this
            width (free voxels a morphological closing of the ink fills); 0 = nearest free
            voxel only.
        center_offset: float, shift of the filament centre from the nozzle tip along the
            printing direction, as a fraction of h_f (0 = centred on the tip; +0.5 = the
            filament's bottom at the tip).
    """

    voxel_mm: float = 0.25
    pad_mm: float = 2.0
    spread_margin_mm: float = 1.0
    max_passes: int = 6
    chunk_segments: int = 60_000
    gap_mm: float = 1.0
    center_offset: float = 0.0

    def __post_init__(self) -> None:
        if not 0.01 <= self.voxel_mm <= 10.0:
            raise InputError(f"voxel size {self.voxel_mm} mm is out of range",
                             "use a voxel between 0.01 and 10 mm (default 0.25)")
        if self.pad_mm < 0 or self.spread_margin_mm <= 0:
            raise ValueError("need pad_mm >= 0 and spread_margin_mm > 0")
        if self.max_passes < 1 or self.chunk_segments < 1:
            raise ValueError("max_passes and chunk_segments must be >= 1")
        if round(0.5 * self.gap_mm / self.voxel_mm) > kernels.MAX_CLOSING:
            raise InputError(f"gaps up to {self.gap_mm} mm are more than "
                             f"{2 * kernels.MAX_CLOSING} voxels of {self.voxel_mm} mm",
                             f"use a voxel of at least "
                             f"{self.gap_mm / (2 * kernels.MAX_CLOSING):.3f} mm or a smaller gap")
        if not -0.5 <= self.center_offset <= 0.5:
            raise InputError(f"filament centre offset {self.center_offset} is out of range",
                             "use -0.5 to 0.5 (a fraction of the filament height; 0 = centred)")


class Segments(NamedTuple):
    """Extruding moves of a toolpath with their filament geometry, in print order.

    start, end: (S, 3) float64, mm, segment end points of the filament centre line (the nozzle
        tip, shifted by ``DepositionConfig.center_offset``).
    tangent: (S, 3) float64, unit direction of motion.
    lateral: (S, 3) float64, unit, across the motion (w_f axis) = tangent x normal.
    up: (S, 3) float64, unit, printing direction made perpendicular to the motion (h_f axis).
    length: (S,) float64, mm.
    speed: (S,) float64, mm/s, mean of the two waypoint speeds.
    width: (S,) float64, mm, filament width w_f.
    height: (S,) float64, mm, filament height h_f.
    volume: (S,) float64, mm^3, C * length / speed.
    layer: (S,) int32, layer of the segment.
    waypoint: (S,) int64, toolpath index of the segment's first waypoint.
    """

    start: NDArray[np.float64]
    end: NDArray[np.float64]
    tangent: NDArray[np.float64]
    lateral: NDArray[np.float64]
    up: NDArray[np.float64]
    length: NDArray[np.float64]
    speed: NDArray[np.float64]
    width: NDArray[np.float64]
    height: NDArray[np.float64]
    volume: NDArray[np.float64]
    layer: NDArray[np.int32]
    waypoint: NDArray[np.int64]


def extrusion_segments(toolpath: Toolpath, morphology: Morphology,
                       center_offset: float = 0.0,
                       segment_speed: NDArray[np.float64] | None = None) -> Segments:
    """The extruding segments of ``toolpath``: consecutive waypoints of one path, both extruding.

    ``center_offset`` (a fraction of h_f) moves the filament centre from the nozzle tip along
    the printing direction; ``start`` and ``end`` are the filament centre line.
    ``segment_speed``: optional (N - 1,) mm/s, the speed each segment i -> i + 1 is actually
    moved at (``sim.as_planned``), instead of the mean of its two waypoints' speeds.

    Raises:
        InputError: an extruding waypoint has a non-positive or non-finite speed, or
            ``segment_speed`` does not have one value per segment.
    """
    n = len(toolpath)
    if segment_speed is not None and np.shape(segment_speed) != (max(n - 1, 0),):
        raise InputError(f"segment speeds have shape {np.shape(segment_speed)}, the toolpath "
                         f"has {max(n - 1, 0)} segments", "re-run mesp plan DIR")
    i = np.arange(max(n - 1, 0))
    dep = (toolpath.path[i] == toolpath.path[i + 1]) & toolpath.extrude[i] & toolpath.extrude[i + 1]
    i = i[dep]
    p0, p1 = toolpath.position[i], toolpath.position[i + 1]
    d = p1 - p0
    length = np.linalg.norm(d, axis=1)
    keep = length > tol.merge
    i, p0, p1, d, length = i[keep], p0[keep], p1[keep], d[keep], length[keep]
    if segment_speed is None:
        speed = 0.5 * (toolpath.speed[i] + toolpath.speed[i + 1])
    else:
        speed = np.asarray(segment_speed, dtype=np.float64)[i]
    if speed.size and not (np.all(np.isfinite(speed)) and speed.min() > 0):
        raise InputError("the toolpath has extruding moves with a non-positive speed",
                         "re-run mesp slice")
    rate = float(morphology.rate_mm3_s)
    tangent = d / length[:, None]
    normal = toolpath.normal[i] + toolpath.normal[i + 1]
    lateral = np.cross(tangent, normal)
    norm = np.linalg.norm(lateral, axis=1)
    bad = norm < tol.parallel * np.maximum(np.linalg.norm(normal, axis=1), 1.0)
    if np.any(bad):
        # Moving along the nozzle axis: any direction across the motion will do.
        helper = np.where(np.abs(tangent[bad, 0:1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        lateral[bad] = np.cross(tangent[bad], helper)
        norm[bad] = np.linalg.norm(lateral[bad], axis=1)
    lateral /= norm[:, None]
    up = np.cross(lateral, tangent)
    w, h = morphology.filament_size(speed)
    w = np.broadcast_to(np.asarray(w, dtype=np.float64), speed.shape).copy()
    h = np.broadcast_to(np.asarray(h, dtype=np.float64), speed.shape).copy()
    # Enforce the area C / v exactly: the morphology fit and the extruder rate must agree,
    # otherwise volume would not be conserved.
    scale = np.sqrt((rate / speed) / (0.25 * np.pi * w * h))
    if center_offset:
        lift = (center_offset * h * scale)[:, None] * up
        p0, p1 = p0 + lift, p1 + lift
    return Segments(
        start=p0, end=p1, tangent=tangent, lateral=lateral, up=up, length=length, speed=speed,
        width=w * scale, height=h * scale, volume=rate * length / speed,
        layer=toolpath.layer[i].astype(np.int32), waypoint=i.astype(np.int64),
    )


class ChunkTrace(NamedTuple):
    """What happened in one chunk.

    layer: int, its layer.
    segments: int, number of segments.
    volume_mm3: float, ink it deposited.
    displaced_mm3: float, ink pushed out of full voxels.
    passes: int, nearest-free passes run.
    max_spread_mm: float, largest distance ink was pushed.
    residual_mm3: float, excess left in over-full voxels (0 unless no room was found).
    """

    layer: int
    segments: int
    volume_mm3: float
    displaced_mm3: float
    passes: int
    max_spread_mm: float
    residual_mm3: float


@dataclass(frozen=True, eq=False)
class Deposit:
    """The simulated print.

    Attributes:
        grid: the voxel grid.
        fill: (nx, ny, nz) float32, ink fraction of each voxel (1 = solid silicone, 0 = gel).
        layer: (nx, ny, nz) int32, the layer that brought most of the voxel's ink (the last
            one whose addition exceeded what the voxel held), -1 = none.
        commanded_mm3: float, sum of C * dt over extruding segments.
        status: ``DepositionStatus.OK``, or ``OVERFULL`` when some excess found no free voxel
            (see ``trace``).
        trace: one ChunkTrace per chunk, in print order.
        timings: stage name -> seconds: segments (and the grid), rasterise (in a worker
            thread, overlapped with the spreading), wait (for the worker, and adding the ink),
            spread.
        segments: number of extruding segments.
    """

    grid: VoxelGrid
    fill: NDArray[np.float32]
    layer: NDArray[np.int32]
    commanded_mm3: float
    status: DepositionStatus
    trace: tuple[ChunkTrace, ...]
    timings: dict[str, float] = field(default_factory=dict)
    segments: int = 0

    @property
    def deposited_mm3(self) -> float:
        """Ink volume on the grid, mm^3."""
        return float(self.fill.sum(dtype=np.float64)) * self.grid.voxel_volume

    @property
    def volume_error(self) -> float:
        """deposited / commanded - 1 (0 for an empty job)."""
        return self.deposited_mm3 / self.commanded_mm3 - 1.0 if self.commanded_mm3 > 0 else 0.0


def job_bounds(segments: Segments) -> NDArray[np.float64]:
    """(2, 3) float64, mm, box holding every swept filament (min, max corner)."""
    if len(segments.length) == 0:
        return np.zeros((2, 3))
    ext = _half_extent(segments)
    lo = np.minimum(segments.start, segments.end) - ext
    hi = np.maximum(segments.start, segments.end) + ext
    return np.stack([lo.min(axis=0), hi.max(axis=0)])


def _half_extent(seg: Segments) -> NDArray[np.float64]:
    """(S, 3) float64, mm, half extent of each cross-section ellipse along x, y, z."""
    a = 0.5 * seg.width[:, None] * seg.lateral
    c = 0.5 * seg.height[:, None] * seg.up
    return np.sqrt(a * a + c * c)


def deposit(toolpath: Toolpath, morphology: Morphology,
            config: DepositionConfig | None = None, grid: VoxelGrid | None = None,
            progress: Progress | None = None,
            segment_speed: NDArray[np.float64] | None = None) -> Deposit:
    """Simulate the print of ``toolpath`` (see the module docstring for the model).

    Args:
        toolpath: waypoints in print order.
        morphology: extrusion rate and filament size at a speed.
        config: settings; defaults if None.
        grid: the voxel grid; by default the job's bounding box plus ``config.pad_mm``.
        progress: receives progress inside the deposition stage.
        segment_speed: optional (N - 1,) mm/s, the speed each segment is actually moved at
            (``sim.as_planned.segment_speeds``: the planned trajectory's), instead of the
            toolpath's; a slower segment lasts longer and deposits C * dt.

    Returns:
        The deposit; volume is conserved (deposited == commanded up to float32 rounding).
    """
    config = config or DepositionConfig()
    progress = progress or NullProgress()
    t0 = time.perf_counter()
    seg = extrusion_segments(toolpath, morphology, config.center_offset, segment_speed)
    if grid is None:
        box = job_bounds(seg)
        grid = VoxelGrid.around(box[0], box[1], config.voxel_mm, config.pad_mm)
    fill = np.zeros(grid.shape, dtype=np.float32)
    tags = np.full(grid.shape, -1, dtype=np.int32)
    timings = {"segments": time.perf_counter() - t0, "rasterise": 0.0, "wait": 0.0,
               "spread": 0.0}
    traces: list[ChunkTrace] = []
    total = len(seg.length)
    extent = _half_extent(seg)
    chunks = _chunks(seg.layer, config.chunk_segments)
    # A chunk's ink does not depend on what is printed already, so a worker thread rasterises
    # the next chunk while this one spreads (the kernels release the GIL). One block table
    # each: a call leaves its table as it found it, but two calls at once must not share one.
    tables = (kernels.block_table(grid.shape), kernels.block_table(grid.shape))
    with ThreadPoolExecutor(max_workers=1) as worker:
        ahead = [worker.submit(_rasterise_chunk, seg, extent, lo, hi, grid, tables[0])
                 for lo, hi in chunks[:1]]
        for n, (lo, hi) in enumerate(chunks):
            t1 = time.perf_counter()
            ink = ahead.pop().result()
            if n + 1 < len(chunks):
                ahead.append(worker.submit(_rasterise_chunk, seg, extent, *chunks[n + 1], grid,
                                           tables[0]))
            layer = int(seg.layer[lo])
            _add_ink(fill, tags, ink, layer, grid)
            t2 = time.perf_counter()
            trace = _spread_chunk(fill, tags, grid, ink.flat, layer, config, tables[1])
            timings["rasterise"] += ink.seconds
            timings["wait"] += t2 - t1
            timings["spread"] += time.perf_counter() - t2
            traces.append(trace._replace(segments=hi - lo,
                                         volume_mm3=float(seg.volume[lo:hi].sum())))
            progress.update(hi / max(total, 1), f"layer {layer}")
    residual = sum(t.residual_mm3 for t in traces)
    fill.setflags(write=False)
    tags.setflags(write=False)
    status = (DepositionStatus.OK if residual <= tol.computed * max(float(seg.volume.sum()), 1.0)
              else DepositionStatus.OVERFULL)
    return Deposit(grid=grid, fill=fill, layer=tags, commanded_mm3=float(seg.volume.sum()),
                   status=status, trace=tuple(traces), timings=timings, segments=total)


def _chunks(layer: NDArray[np.int32], size: int) -> list[tuple[int, int]]:
    """[lo, hi) index ranges: runs of equal layer, split into pieces of at most ``size``."""
    if layer.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(layer)) + 1
    edges = np.concatenate([[0], breaks, [layer.size]])
    out: list[tuple[int, int]] = []
    for a, b in itertools.pairwise(edges.tolist()):
        pieces = int(np.ceil((b - a) / size))
        cuts = np.linspace(a, b, pieces + 1).round().astype(int)
        out.extend(zip(cuts[:-1].tolist(), cuts[1:].tolist(), strict=True))
    return out


class ChunkInk(NamedTuple):
    """The ink one chunk brings.

    flat: (V,) int64, the voxels it goes to; volume: (V,) float64, mm^3 each.
    seconds: float, time the rasterisation took.
    """

    flat: NDArray[np.int64]
    volume: NDArray[np.float64]
    seconds: float


def _rasterise_chunk(seg: Segments, extent: NDArray[np.float64], lo: int, hi: int,
                     grid: VoxelGrid, table: NDArray[np.int32]) -> ChunkInk:
    """The ink of segments [lo, hi) per voxel (``kernels.rasterise``)."""
    t0 = time.perf_counter()
    shape = np.asarray(grid.shape)
    vox = grid.voxel
    org = grid.origin_array
    p0, p1 = seg.start[lo:hi], seg.end[lo:hi]
    ext = extent[lo:hi] + 0.5 * vox  # centres up to half a voxel outside get partial ink
    vlo = np.ceil((np.minimum(p0, p1) - ext - org) / vox - 0.5).astype(np.int64)
    vhi = np.floor((np.maximum(p0, p1) + ext - org) / vox - 0.5).astype(np.int64)
    vlo = np.clip(vlo, 0, shape - 1)
    vhi = np.clip(vhi, -1, shape - 1)
    # Fallback voxel (midpoint) for filaments thinner than the grid resolves.
    mid = np.clip(np.floor((0.5 * (p0 + p1) - org) / vox).astype(np.int64), 0, shape - 1)
    flat, ink = kernels.rasterise(
        p0, seg.tangent[lo:hi], seg.lateral[lo:hi], seg.up[lo:hi], seg.length[lo:hi],
        seg.width[lo:hi], seg.height[lo:hi], seg.volume[lo:hi], vlo, vhi, mid, org, vox,
        grid.shape, table)
    return ChunkInk(flat, ink, time.perf_counter() - t0)


def _add_ink(fill: NDArray[np.float32], tags: NDArray[np.int32], ink: ChunkInk, layer: int,
             grid: VoxelGrid) -> None:
    """Add a chunk's ink to ``fill``; a voxel belongs to the layer that brought most of it."""
    kernels.add_ink(fill.reshape(-1), tags.reshape(-1), ink.flat, ink.volume,
                    1.0 / grid.voxel_volume, layer)


def _spread_chunk(fill: NDArray[np.float32], tags: NDArray[np.int32], grid: VoxelGrid,
                  touched: NDArray[np.int64], layer: int, config: DepositionConfig,
                  table: NDArray[np.int32]) -> ChunkTrace:
    """Push the excess of the over-full voxels among ``touched`` into nearby voxels with room
    (``kernels.spread``: regions, nearest first, gaps and grooves of the ink first)."""
    vox = grid.voxel
    margin = max(1, int(np.ceil(config.spread_margin_mm / vox)))
    closing = round(0.5 * config.gap_mm / vox)
    done = kernels.spread(fill.reshape(-1), tags.reshape(-1), grid.shape, table, touched,
                          layer, margin, closing, config.max_passes, FULL, OVERFULL)
    return ChunkTrace(layer=layer, segments=0, volume_mm3=0.0,
                      displaced_mm3=done.displaced * grid.voxel_volume, passes=done.passes,
                      max_spread_mm=float(np.sqrt(done.max_d2)) * vox,
                      residual_mm3=done.residual * grid.voxel_volume)


def covering_grid(toolpath: Toolpath, morphology: Morphology,
                  extra: NDArray[np.float64] | None = None,
                  config: DepositionConfig | None = None,
                  max_voxels: int = MAX_VOXELS,
                  segment_speed: NDArray[np.float64] | None = None) -> VoxelGrid:
    """The grid holding every filament of ``toolpath`` (moved at ``segment_speed``, see
    ``deposit``) and the box ``extra`` ((2, 3) mm).

    Raises:
        InputError: the grid would have more than ``max_voxels`` voxels of ``config.voxel_mm``
            (the default bounds what the inspection's metrics can handle).
    """
    config = config or DepositionConfig()
    box = job_bounds(extrusion_segments(toolpath, morphology, config.center_offset,
                                        segment_speed))
    if extra is not None:
        extra = np.asarray(extra, dtype=np.float64)
        box = np.stack([np.minimum(box[0], extra[0]), np.maximum(box[1], extra[1])])
    return VoxelGrid.around(box[0], box[1], config.voxel_mm, config.pad_mm, max_voxels)
