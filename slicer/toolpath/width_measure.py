"""Width error of printed lines: the spacing to the neighbouring line against the mean of
the two lines' widths, and a lone line against the width of the band it fills."""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.medial import across_width
from slicer.toolpath.width_error import LineNeighbours, band_width, line_neighbours

LONE_LINE = 2.0  # no other line within this x W: the line fills its band alone
NEIGHBOUR_ANGLE = 45.0  # deg: a line met at a steeper angle is no neighbour (a junction)


class MeasuredWidth(NamedTuple):
    """Width error at the line points with a measured spacing (dimensionless)."""

    error: NDArray[np.float64]  # (k,) |spacing - target| / target, target the pair's mean W
    pointwise: NDArray[np.float64]  # (k,) |spacing - W| / W, W at the point alone
    lone: int  # how many of the k points are on lone lines, measured by their band


def measure_width(lines: SurfaceLines, width_pt: NDArray[np.float64],
                  normals_pt: NDArray[np.float64],
                  boundary: Callable[[], tuple[NDArray[np.float64], NDArray[np.float64]]],
                  junctions: bool = False) -> MeasuredWidth:
    """The width error of ``lines`` printed at ``width_pt`` ((P,) float64 mm).

    Two neighbouring lines tile the layer when they lie (W_a + W_b) / 2 apart, each covering
    half its own width on either side; that mean, of the width at the point and at its foot
    on the neighbouring line, is the target of the spacing. Measured against the point's W
    alone (``pointwise``, the measure before session 13), a layer whose W changes across
    one spacing is always off: its nearest neighbour lies on the narrower side, half the
    change away from W (the membrane's dome layers, W 2.5-7 mm: -10 % on every interior
    ring, however well the lines follow eq. 14).

    A lone line fills a band about one width wide by itself (a thin wall, a tube's shell):
    its nearest other line lies across the part, not beside it, so its spacing is the
    band's width there: the distances to the boundary on its two sides (Euclidean: exact
    on flat layers, and a band that thin is nearly flat across), against its own W; near a
    line's end, where the nearest boundary lies ahead of the point (the end of the strip),
    from one side to the other across the line (``medial.across_width``).
    ``boundary`` gives the (B, 3) mm ends a, b of the original layer's boundary segments
    (called when needed).

    With ``junctions`` (medial lines of walls meeting one another), a line met end-on (at
    more than NEIGHBOUR_ANGLE: a wall joining another) is no neighbour where the point's
    line fills its band alone: the distance to it is no spacing. Elsewhere such a point
    keeps it (a ring's corner facing the next ring's, stripes converging: what is measured
    there is real overlap or gap).
    """
    if len(lines.points) < 2:
        return MeasuredWidth(np.zeros(0), np.zeros(0), 0)
    near = line_neighbours(lines.points, lines.line, normals_pt, closed=lines.closed)
    spacing = near.spacing.copy()
    target = 0.5 * (width_pt + near.at_foot(width_pt))
    lone = ~np.isfinite(spacing) | (spacing > LONE_LINE * width_pt)
    end_on = ~lone & ~_parallel(lines, near) if junctions else np.zeros_like(lone)
    if lone.any() or end_on.any():
        a, b = boundary()
        some = np.flatnonzero(lone | end_on)
        across, ahead = across_width(lines.points, lines.line, normals_pt, a, b, some)
        band = np.full(len(spacing), np.nan)
        band[some] = np.where(ahead & np.isfinite(across), across,
                              band_width(lines.points[some], a, b))
        lone |= end_on & (band < LONE_LINE * width_pt)
        spacing[lone] = band[lone]
        target[lone] = width_pt[lone]
    ok = np.isfinite(spacing) & (width_pt > 0) & (target > 0)
    return MeasuredWidth(np.abs(spacing[ok] - target[ok]) / target[ok],
                         np.abs(spacing[ok] - width_pt[ok]) / width_pt[ok],
                         int(np.count_nonzero(lone & ok)))


def _parallel(lines: SurfaceLines, near: LineNeighbours) -> NDArray[np.bool_]:
    """(P,) bool, the neighbouring line runs within NEIGHBOUR_ANGLE of the point's line
    there (True where there is no neighbour or a direction is undefined): a line met end-on
    (a wall joining another at a junction, a line running into another) is no neighbour
    beside it, and the distance to it no spacing."""
    p = lines.points
    n = len(p)
    line = lines.line
    i = np.arange(n)
    start = np.flatnonzero(np.concatenate([[True], line[1:] != line[:-1]]))
    stop = np.concatenate([start[1:], [n]])
    first = np.repeat(start, stop - start)
    last = np.repeat(stop - 1, stop - start)
    own = p[np.minimum(i + 1, last)] - p[np.maximum(i - 1, first)]
    j = near.near
    other = p[np.minimum(j + 1, last[j])] - p[np.maximum(j - 1, first[j])]
    norm = np.linalg.norm(own, axis=1) * np.linalg.norm(other, axis=1)
    cos = np.abs(np.einsum("ij,ij->i", own, other)) / np.maximum(norm, 1e-300)
    return (cos >= np.cos(np.radians(NEIGHBOUR_ANGLE))) | (norm <= 0.0) | (j == i)
