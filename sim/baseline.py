"""The planar baseline: what a commercial slicer does for embedded printing (paper 2.1, 3.2).

The model is cut by horizontal planes at a constant layer height H. Each layer gets
``perimeters`` boundary-parallel contour lines and a raster infill whose direction turns by
90 deg from layer to layer, all at one constant line width W and one constant speed v:

* ``width_mode="overlap"`` (a commercial thin-wall setting): the filament at speed v has height
  h_f = H / beta and the lines overlap by the same ratio, W = beta * w_f (paper section 3.2).
  At the volume-matching overlap beta = sqrt(pi) / 2 (the default) the ink per millimetre equals
  W * H; a smaller beta over-extrudes by pi / (4 beta^2), a larger one under-extrudes.
* ``width_mode="volume"``: W = C / (H v), the paper's volume-preserving width on planar layers.

Both modes are honest planar strategies; ``mesp inspect --baseline planar`` runs both (the
volume mode flushed like a curved job when the tet mesh is at hand, ``slicer.toolpath.flush``)
and keeps the one with the lower surface error. Known limits, for and against the baseline,
reported rather than hidden:

* Thin walls: a wall narrower than one line width W gets no perimeter (the first perimeter
  sits at inset W / 2). Like the thin-wall options of commercial slicers, ``thin_walls``
  prints one line along the middle of such walls where they separate the outside from a hole
  (tube walls: the aorta's 2.5 mm wall is thinner than the "volume" mode's W = 2.6 mm at
  H = 0.65 mm, which without it printed 16 % of the model). Thin strips without a hole on
  the other side are not handled.
* The deposition model fuses any two filaments that overlap, however little. The paper
  (section 3.2, figure 3(a)) observes insufficient fusion at small overlaps (beta = 0.9), the
  regime of the volume-matching overlap beta = 0.886, so the simulated "overlap" baseline is
  an optimistic bound for a real planar print.

The nozzle is vertical (normal +z). Everything is vectorised per layer: the section is
rasterised onto a fine 2D grid by scan-line parity, a 2D distance transform gives the inset
distance, the perimeters are its iso-lines (contourpy, shipped with matplotlib) and the raster
lines are the runs of grid rows that lie deep enough inside.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Literal

import contourpy
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from core.errors import InputError
from core.stages import Pattern, Toolpath
from core.tolerance import tol
from sim.deposition import Morphology

VOLUME_MATCHING_BETA = float(np.sqrt(np.pi) / 2.0)


@dataclass(frozen=True)
class PlanarConfig:
    """Settings of the planar baseline slicer.

    Attributes:
        layer_height_mm: float, mm, target constant layer height H (adjusted so an integer
            number of layers spans the model).
        beta: float, overlap ratio H = beta * h_f, and W = beta * w_f in "overlap" mode.
        width_mode: "overlap" (W = beta * w_f) or "volume" (W = C / (H v)).
        perimeters: int, contour lines per layer (0 = raster only).
        spacing_mm: float, mm, waypoint spacing along lines.
        raster_angle_deg: float, deg, raster direction of layer 0 (0 = along x), +90 per layer.
        resolution: float, 2D grid step as a fraction of W (inset accuracy).
        min_line_mm: float, mm, shorter raster runs and perimeter loops are dropped.
        thin_walls: bool, a centre line on walls thinner than W between outside and a hole.
    """

    layer_height_mm: float = 0.6
    beta: float = VOLUME_MATCHING_BETA
    width_mode: Literal["overlap", "volume"] = "overlap"
    perimeters: int = 1
    spacing_mm: float = 0.4
    raster_angle_deg: float = 0.0
    resolution: float = 0.1
    min_line_mm: float = 0.5
    thin_walls: bool = True

    def __post_init__(self) -> None:
        if not 0.02 <= self.layer_height_mm <= 20:
            raise InputError(f"baseline layer height {self.layer_height_mm} mm",
                             "use 0.02 to 20 mm")
        if not 0.1 <= self.beta <= 1.0:
            raise InputError(f"baseline beta {self.beta}", "use 0.1 <= beta <= 1")
        if self.width_mode not in ("overlap", "volume"):
            raise InputError(f"width mode '{self.width_mode}'", "use overlap or volume")
        if self.perimeters < 0 or self.spacing_mm <= 0 or not 0 < self.resolution <= 0.5:
            raise ValueError("need perimeters >= 0, spacing_mm > 0, 0 < resolution <= 0.5")


def speed_for_height(morphology: Morphology, h_f: float, lo: float = 1e-3,
                     hi: float = 1e4) -> float:
    """mm/s at which the filament height is ``h_f`` (bisection; h_f falls as speed rises).

    Uses the profile's own inverse when it has one; clamped to [lo, hi] mm/s when the
    morphology cannot reach ``h_f``.
    """
    inverse = getattr(morphology, "speed_for_height", None)
    if callable(inverse):
        return float(np.clip(np.asarray(inverse(h_f), dtype=np.float64).ravel()[0], lo, hi))
    a, b = np.log(lo), np.log(hi)
    for _ in range(80):
        mid = 0.5 * (a + b)
        h = float(np.asarray(morphology.filament_size(np.array([np.exp(mid)]))[1]).ravel()[0])
        if h > h_f:
            a = mid
        else:
            b = mid
    return float(np.exp(0.5 * (a + b)))


def line_parameters(morphology: Morphology, config: PlanarConfig) -> tuple[float, float]:
    """(speed v mm/s, width W mm) of the baseline's constant lines."""
    h = config.layer_height_mm
    v = speed_for_height(morphology, h / config.beta)
    w_f = float(np.asarray(morphology.filament_size(np.array([v]))[0]).ravel()[0])
    if config.width_mode == "overlap":
        return v, config.beta * w_f
    return v, float(morphology.rate_mm3_s) / (h * v)


def section_segments(triangles: NDArray[np.float64], z: float) -> NDArray[np.float64]:
    """(m, 2, 2) float64, mm: xy end points where the plane z = ``z`` cuts (F, 3, 3) triangles."""
    d = triangles[:, :, 2] - z
    d = np.where(d == 0.0, tol.zero, d)  # a vertex on the plane counts as just above it
    above = d > 0
    n_above = above.sum(axis=1)
    cut = (n_above == 1) | (n_above == 2)
    tri, d, above = triangles[cut], d[cut], above[cut]
    pts = []
    for a, b in ((0, 1), (1, 2), (2, 0)):
        crosses = above[:, a] != above[:, b]
        t = d[:, a] / np.where(crosses, d[:, a] - d[:, b], 1.0)
        p = tri[:, a, :2] + t[:, None] * (tri[:, b, :2] - tri[:, a, :2])
        pts.append(np.where(crosses[:, None], p, np.nan))
    stacked = np.stack(pts, axis=1)  # (m, 3, 2), exactly two rows valid
    valid = ~np.isnan(stacked[:, :, 0])
    order = np.argsort(~valid, axis=1, kind="stable")[:, :2]
    return np.take_along_axis(stacked, order[:, :, None], axis=1)


def rasterise_section(segments: NDArray[np.float64], x: NDArray[np.float64],
                      y: NDArray[np.float64]) -> NDArray[np.bool_]:
    """(len(x), len(y)) bool, grid points inside the closed section (parity along x).

    Args:
        segments: (m, 2, 2) float64, mm, section edges.
        x, y: (nx,), (ny,) float64, mm, increasing uniform grid coordinates.
    """
    nx, ny = len(x), len(y)
    toggles = np.zeros((ny, nx + 1), dtype=np.int64)
    if len(segments):
        g = y[1] - y[0] if ny > 1 else 1.0
        gx = x[1] - x[0] if nx > 1 else 1.0
        y0, y1 = segments[:, 0, 1], segments[:, 1, 1]
        ylo, yhi = np.minimum(y0, y1), np.maximum(y0, y1)
        jitter = 1e-7 * np.sqrt(2.0) * g
        jlo = np.ceil((ylo - y[0] - jitter) / g).astype(np.int64)
        jhi = np.ceil((yhi - y[0] - jitter) / g).astype(np.int64) - 1  # rows in [ylo, yhi)
        jlo, jhi = np.maximum(jlo, 0), np.minimum(jhi, ny - 1)
        count = np.maximum(jhi - jlo + 1, 0)
        owner = np.repeat(np.arange(len(segments)), count)
        row = jlo[owner] + np.arange(owner.size) - np.repeat(np.cumsum(count) - count, count)
        yr = y[0] + row * g + jitter
        s = segments[owner]
        t = (yr - s[:, 0, 1]) / (s[:, 1, 1] - s[:, 0, 1])
        xc = s[:, 0, 0] + t * (s[:, 1, 0] - s[:, 0, 0])
        col = np.clip(np.ceil((xc - x[0]) / gx), 0, nx).astype(np.int64)
        np.add.at(toggles, (row, col), 1)
    parity = np.cumsum(toggles & 1, axis=1)[:, :nx] & 1
    return parity.T.astype(bool)


def _runs(mask: NDArray[np.bool_]) -> tuple[NDArray[np.int64], NDArray[np.int64],
                                            NDArray[np.int64]]:
    """Runs of True along axis 1 of (r, n) ``mask``: (row, first, last) index arrays."""
    pad = np.zeros((mask.shape[0], 1), dtype=bool)
    edge = np.diff(np.concatenate([pad, mask, pad], axis=1).astype(np.int8), axis=1)
    rs, starts = np.nonzero(edge == 1)
    _, ends = np.nonzero(edge == -1)
    return rs, starts, ends - 1


def _resample(poly: NDArray[np.float64], spacing: float) -> NDArray[np.float64]:
    """Points every ~``spacing`` along a polyline (n, 2), keeping both ends."""
    seg = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    count = max(int(np.ceil(s[-1] / spacing)), 1)
    t = np.linspace(0.0, s[-1], count + 1)
    return np.stack([np.interp(t, s, poly[:, 0]), np.interp(t, s, poly[:, 1])], axis=1)


def planar_toolpath(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                    morphology: Morphology, config: PlanarConfig | None = None) -> Toolpath:
    """Slice a closed mesh in planar layers into perimeters + alternating raster lines.

    Args:
        vertices: (V, 3) float64, mm.
        faces: (F, 3) int.
        morphology: extrusion rate and filament size.
        config: baseline settings.

    Returns:
        The toolpath (normal +z, constant height, width and speed).
    """
    config = config or PlanarConfig()
    vertices = np.asarray(vertices, dtype=np.float64)
    tri = vertices[np.asarray(faces, dtype=np.int64)]
    zmin, zmax = float(vertices[:, 2].min()), float(vertices[:, 2].max())
    n_layers = max(1, round((zmax - zmin) / config.layer_height_mm))
    h = (zmax - zmin) / n_layers
    speed, width = line_parameters(morphology, _with_height(config, h))
    g = config.resolution * width
    lo, hi = vertices[:, :2].min(axis=0) - 2 * g, vertices[:, :2].max(axis=0) + 2 * g
    x = np.arange(lo[0], hi[0] + g, g)
    y = np.arange(lo[1], hi[1] + g, g)

    def layer_lines(k: int) -> list[tuple[NDArray[np.float64], int, int]]:
        """(points (n, 3), layer, pattern) of the lines of layer ``k``, in print order."""
        z = zmin + (k + 0.5) * h
        inside = rasterise_section(section_segments(tri, z), x, y)
        if not inside.any():
            return []
        sdf = _section_distance(inside) * g
        walls = _thin_walls(inside, x, y, width, config) if config.thin_walls else []
        out: list[tuple[NDArray[np.float64], int, int]] = []
        for poly in _perimeters(sdf, x, y, width, config) + walls:
            pts = _resample(poly, config.spacing_mm)
            out.append((np.column_stack([pts, np.full(len(pts), z)]), k, Pattern.CONTOUR))
        angle = np.deg2rad(config.raster_angle_deg) + 0.5 * np.pi * (k % 2)
        for seg in _raster(sdf, x, y, width, config, along_x=abs(np.cos(angle)) > 0.5, flip=k):
            pts = _resample(seg, config.spacing_mm)
            out.append((np.column_stack([pts, np.full(len(pts), z)]), k, Pattern.STRIPE))
        return out

    # Layers are independent and the distance transforms release the GIL: threads, in order.
    with ThreadPoolExecutor(max_workers=min(4, os.cpu_count() or 1)) as pool:
        lines = [line for layer in pool.map(layer_lines, range(n_layers)) for line in layer]
    return _assemble(lines, h, width, speed)


def _section_distance(inside: NDArray[np.bool_]) -> NDArray[np.float64]:
    """Signed distance to the section edge in grid steps (> 0 inside): the edge lies half a
    step beyond the last inside grid point.

    Outside, only the values next to the section are ever read (the perimeters are iso-lines
    at positive levels, the raster ends interpolate between neighbours): the grid points
    4-adjacent to an inside point are 1 step from it, the diagonal ones sqrt(2); the rest get
    -1.5, which saves the outside's distance transform.
    """
    sdf = np.where(inside, ndimage.distance_transform_edt(inside) - 0.5, -1.5)
    cross = ndimage.binary_dilation(inside) & ~inside
    diagonal = ndimage.binary_dilation(inside, structure=np.ones((3, 3), dtype=bool))
    sdf[diagonal & ~inside & ~cross] = 0.5 - np.sqrt(2.0)
    sdf[cross] = -0.5
    return sdf


def _with_height(config: PlanarConfig, h: float) -> PlanarConfig:
    from dataclasses import replace

    return replace(config, layer_height_mm=h)


def _perimeters(sdf: NDArray[np.float64], x: NDArray[np.float64], y: NDArray[np.float64],
                width: float, config: PlanarConfig) -> list[NDArray[np.float64]]:
    """Closed contour lines at inset (i + 0.5) * W, outermost first."""
    if config.perimeters == 0:
        return []
    gen = contourpy.contour_generator(x, y, sdf.T, line_type="Separate")
    out = []
    for i in range(config.perimeters):
        for loop in gen.lines((i + 0.5) * width):
            loop = np.asarray(loop, dtype=np.float64)
            if np.linalg.norm(np.diff(loop, axis=0), axis=1).sum() >= config.min_line_mm:
                out.append(loop)
    return out


def _thin_walls(inside: NDArray[np.bool_], x: NDArray[np.float64], y: NDArray[np.float64],
                width: float, config: PlanarConfig) -> list[NDArray[np.float64]]:
    """Centre lines of the walls thinner than ``width`` that separate the outside from a hole.

    The centre is the zero set of d_out - d_hole (grid distances to the outside and to the
    holes); a wall is thin where d_out + d_hole, its local thickness, is below ``width``, so
    no perimeter fits. Pieces shorter than ``config.min_line_mm`` are dropped.
    """
    gel = ~inside
    label, _ = ndimage.label(gel)
    border = np.unique(np.concatenate([label[0], label[-1], label[:, 0], label[:, -1]]))
    outside = np.isin(label, border[border > 0])
    holes = gel & ~outside
    if not holes.any():
        return []
    g = float(x[1] - x[0])
    # A thin point p has d_out(p) + d_hole(p) - g < W; its nearest outside point o is
    # 4-adjacent to the section (its neighbour towards p is nearer to p, so not outside, and
    # not a hole, which would join the outside's component) and d_hole(o) < W + g. None such:
    # no thin wall, and the outside's distance transform is not needed. Checked on blocks of
    # cells first (a lower bound of d_hole, 16 times cheaper), then exactly.
    shore = outside & ndimage.binary_dilation(inside)
    if not np.any(_hole_distance_bound(holes)[shore] * g < width + g):
        return []
    d_hole = ndimage.distance_transform_edt(~holes) * g
    if not np.any(d_hole[shore] < width + g):
        return []
    d_out = ndimage.distance_transform_edt(~outside) * g
    # Grid distances run centre to centre: the wall is one cell thinner than their sum.
    thin = inside & (d_out + d_hole - g < width)
    if not thin.any():
        return []
    near = ndimage.binary_dilation(thin)
    field = np.ma.masked_array(d_out - d_hole, mask=~near)
    gen = contourpy.contour_generator(x, y, field.T, line_type="Separate")
    out = []
    for line in gen.lines(0.0):
        line = np.asarray(line, dtype=np.float64)
        i = np.clip(np.rint((line[:, 0] - x[0]) / g).astype(np.int64), 0, len(x) - 1)
        j = np.clip(np.rint((line[:, 1] - y[0]) / g).astype(np.int64), 0, len(y) - 1)
        keep = near[i, j]
        pad = np.concatenate([[False], keep, [False]]).astype(np.int8)
        starts, ends = np.flatnonzero(np.diff(pad) == 1), np.flatnonzero(np.diff(pad) == -1)
        for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
            piece = line[a:b]
            if len(piece) > 1 and np.linalg.norm(np.diff(piece, axis=0),
                                                  axis=1).sum() >= config.min_line_mm:
                out.append(piece)
    return out


def _hole_distance_bound(holes: NDArray[np.bool_], block: int = 4) -> NDArray[np.float64]:
    """A lower bound of each cell's distance to ``holes`` (cells), from a distance transform
    on ``block`` x ``block`` blocks: a cell and a hole cell lie within block / sqrt(2) of
    their blocks' centres, so the cells are at least (block distance - sqrt(2)) * block apart.
    """
    nx, ny = holes.shape
    bx, by = -(-nx // block), -(-ny // block)
    padded = np.zeros((bx * block, by * block), dtype=bool)
    padded[:nx, :ny] = holes
    coarse = padded.reshape(bx, block, by, block).any(axis=(1, 3))
    bound = (ndimage.distance_transform_edt(~coarse) - np.sqrt(2.0)) * block
    full = np.repeat(np.repeat(bound, block, axis=0), block, axis=1)[:nx, :ny]
    return np.asarray(full, dtype=np.float64)


def _raster(sdf: NDArray[np.float64], x: NDArray[np.float64], y: NDArray[np.float64],
            width: float, config: PlanarConfig, along_x: bool, flip: int
            ) -> list[NDArray[np.float64]]:
    """Raster runs at spacing W inside the perimeters, boustrophedon order."""
    level = config.perimeters * width
    field, u, w = (sdf, x, y) if along_x else (sdf.T, y, x)  # field[u-index, w-index]
    inside_w = np.flatnonzero((field > level).any(axis=0))
    if inside_w.size == 0:
        return []
    w_lo, w_hi = w[inside_w[0]] - 0.5 * (w[1] - w[0]), w[inside_w[-1]] + 0.5 * (w[1] - w[0])
    n = max(1, round((w_hi - w_lo) / width))
    rows = w_lo + (np.arange(n) + 0.5) * (w_hi - w_lo) / n
    # Linear interpolation of the field onto the raster rows (rows along u).
    fi = np.clip((rows - w[0]) / (w[1] - w[0]), 0, len(w) - 1.000001)
    j0 = np.floor(fi).astype(np.int64)
    frac = fi - j0
    vals = field[:, j0].T * (1 - frac[:, None]) + field[:, j0 + 1].T * frac[:, None]  # (n, nu)
    r, a, b = _runs(vals > level)

    def crossing(i_in: NDArray[np.int64], i_out: NDArray[np.int64]) -> NDArray[np.float64]:
        ok = (i_out >= 0) & (i_out < len(u))
        io = np.clip(i_out, 0, len(u) - 1)
        f_in, f_out = vals[r, i_in], vals[r, io]
        t = np.where(ok, (f_in - level) / np.where(f_in != f_out, f_in - f_out, 1.0), 0.0)
        return u[i_in] + t * (u[io] - u[i_in])

    start, end = crossing(a, a - 1), crossing(b, b + 1)
    keep = end - start >= config.min_line_mm
    out = []
    for idx, (rr, s0, s1) in enumerate(zip(r[keep], start[keep], end[keep], strict=True)):
        if (idx + flip) % 2:
            s0, s1 = s1, s0
        seg_u = np.array([s0, s1])
        seg_w = np.full(2, rows[rr])
        out.append(np.column_stack([seg_u, seg_w] if along_x else [seg_w, seg_u]))
    return out


def _assemble(lines: list[tuple[NDArray[np.float64], int, int]], h: float, width: float,
              speed: float) -> Toolpath:
    """One Toolpath from per-line point arrays: one path per line, in order."""
    if not lines:
        raise InputError("the planar baseline found no printable region",
                         "check the model is closed and larger than the line width")
    pos = np.concatenate([p for p, _, _ in lines])
    counts = np.array([len(p) for p, _, _ in lines])
    n = len(pos)
    return Toolpath(
        position=pos,
        normal=np.tile([0.0, 0.0, 1.0], (n, 1)),
        layer=np.repeat([k for _, k, _ in lines], counts),
        path=np.repeat(np.arange(len(lines)), counts),
        height=np.full(n, h),
        width=np.full(n, width),
        speed=np.full(n, speed),
        extrude=np.ones(n, dtype=bool),
        pattern=np.repeat([pt for _, _, pt in lines], counts),
    )
