"""Boundary contour of stripe layers (issues #3/#6).

Stripes cross the layer and meet its boundary only through U-turn connectors, so the edge
of a stripe layer comes out scalloped (notches in side walls, lobes out of the surface).
With ``ToolpathConfig.stripe_perimeter`` a stripe layer gets one boundary-following loop
at distance spacing / 2 from the boundary (the iso-line of the in-layer boundary distance,
eq. 9 with a single level; one loop per boundary loop) and its stripes are clipped where
that distance drops below PERIMETER_CLIP * spacing. Clipping uses the distance field
interpolated along the lines (not 3-D distance): a line point keeps its face and
barycentrics, and each cut point is placed exactly where the linear interpolant crosses
the threshold inside the triangle the segment lies in. ``build`` merges loop and clipped
stripes into one set of lines: the volume match covers both, the loop is printed first
(``ordering``: closed lines first, the loop entered where it comes closest to a chain end,
so the connector into the stripes extrudes) and the stripes are joined by U-turns inside
the loop. The loop's waypoints carry the stripe pattern code (its layer is a stripe layer).

PERIMETER_CLIP = 1.5 rather than the 0.75 of the first experiment (which cut the U-turns
away, leaving the stripes unjoined): here the U-turns stay and run along the clip line, so
their band [c - W/2, c + W/2] clears the loop's band [0, W] at c = 1.5 W; at 0.75 W they
overlapped it and the volume match widened the stripe spacing to tau 1.4-1.5.
Measured on the hemisphere example (``mesp slice examples/hemisphere.stl --job
examples/hemisphere.toml`` then ``mesp inspect --baseline planar``), clip factor ->
(surface error mean mm, infill %, stripe tau): off 0.189 / 97.83 / 1.2-1.3, 0.75 0.183 /
97.84 / 1.4-1.5, 1.0 0.173 / 97.95, 1.25 0.165 / 98.06, 1.5 0.160 / 98.10 / 1.1-1.2,
1.75 0.158 / 98.14 (pores 0.06 -> 0.14 %, stripe width error p50 0.18 -> 0.30); with the
loop entered next to a chain end (1.5, as committed): 0.156 / 98.14, extrusion starts
34 -> 38. Socket example: stripe-layer starts 259 -> 238, volume error within 0.2 %, but
stripe width error p90 12.1 -> 17.2 % (the loop's spacing to the stripes and the outermost
stripe running parallel to the boundary, which lies 1.5-2.5 spacings from it, measure wide).

Narrow components get no loop (PERIMETER_MIN_DISTANCE): on a band a few W wide (the socket's
annular layers are 3.9-4.9 W) two loops take 2 W, the clip leaves stubs about 1.5 W long, and
the U-turn connectors along the clip line become most of the volume; the deposited volume
then jumps by +-15 % between spacings 0.5 % apart (one join more or less), the volume match
needed 17 trials instead of 3, and the toolpath stage took 27 % longer for nothing a zig-zag
across the band does not already give. With the threshold the socket's toolpath stage is as
fast with the option as without (70.1 s idle, bench/run.py).

Off by default: the clip is by distance only, so on a side that runs parallel to the stripes
(the cube's) the outermost stripe may lie 1.5-2.5 spacings from the boundary, leaving a gap
after the loop at 0.5: cube (``mesp inspect``) pores 0.08 -> 0.83 %, surface error 0.201 ->
0.213 mm, stripe width p90 53 -> 66 %; actuator stripe p90 34 -> 46 %. Clipping only the
stripe ends that meet the boundary end-on would fix that; not done yet.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slicer.toolpath.isolines import iso_lines
from slicer.toolpath.lines import SurfaceLines, empty_lines
from slicer.toolpath.mapback import interpolate
from slicer.toolpath.resample import common_face, face_neighbours, line_index

PERIMETER_CLIP = 1.5  # stripes are clipped where the boundary distance < this x spacing
PERIMETER_MIN_DISTANCE = 3.0  # a loop only where the largest boundary distance >= this x W


def perimeter_loop(vertices: NDArray[np.float64], faces: NDArray[np.int32],
                   distance: NDArray[np.float64], spacing: float) -> SurfaceLines:
    """The iso-line distance = spacing / 2 (one loop per boundary loop), empty when the
    component is narrower than that."""
    level = 0.5 * spacing
    if len(distance) == 0 or float(distance.max()) <= level:
        return empty_lines()
    return iso_lines(vertices, faces, distance, np.array([level]))


def clip_lines(lines: SurfaceLines, vertices: NDArray[np.float64], faces: NDArray[np.int32],
               distance: NDArray[np.float64], threshold: float,
               neighbours: NDArray[np.int64] | None = None) -> SurfaceLines:
    """The parts of ``lines`` where the per-vertex ``distance`` (linear in each face) is at
    least ``threshold``; cut points are inserted on the threshold.

    Args:
        lines: polylines on the mesh (consecutive points share a triangle, as iso-lines do).
        vertices: (n, 3) float64, mm; faces: (m, 3) int32.
        distance: (n,) float64, mm, e.g. the boundary distance.
        threshold: mm.
        neighbours: (m, 3) int64 from ``face_neighbours`` (computed if None).

    Returns:
        New SurfaceLines; a closed line wholly kept stays closed, a clipped one becomes one
        open line per kept run (the run through its seam comes out as two lines meeting at
        the seam point).
    """
    if len(lines.points) == 0:
        return lines
    if neighbours is None:
        neighbours = face_neighbours(faces)
    idx = line_index(lines)
    n_pts = len(lines.points)
    # augmented order: a closed line repeats its first point at its end (closing segment)
    closed_ids = np.flatnonzero(lines.closed & (idx.stop > idx.start))
    order = np.argsort(np.concatenate([np.arange(n_pts, dtype=np.float64),
                                       idx.stop[closed_ids] - 0.5]), kind="stable")
    src = np.concatenate([np.arange(n_pts), idx.start[closed_ids]])[order]
    line = lines.line[src]
    pts, face, bary = lines.points[src], lines.face[src], lines.bary[src]
    d = interpolate(distance, faces, face, bary)
    inside = d >= threshold
    if np.all(inside):
        return lines
    # crossings on segments (i, i + 1) of one line whose ends lie on different sides
    seg = np.flatnonzero((line[1:] == line[:-1]) & (inside[1:] != inside[:-1]))
    t = (threshold - d[seg]) / (d[seg + 1] - d[seg])
    t = np.clip(t, 0.0, 1.0)
    cf, ba, bb, ok = common_face(pts[seg], pts[seg + 1], face[seg], face[seg + 1],
                                  vertices, faces, neighbours)
    c_bary = (1.0 - t)[:, None] * ba + t[:, None] * bb
    c_face = cf.copy()
    # no shared triangle (should not happen for iso-lines): the nearer end's triangle
    near = np.where(t < 0.5, seg, seg + 1)
    c_face[~ok] = face[near[~ok]]
    c_bary[~ok] = bary[near[~ok]]
    c_pts = interpolate(vertices, faces, c_face, c_bary)
    # merge the kept points and the cut points in line order; a dropped point breaks a run
    key = np.concatenate([np.arange(len(src), dtype=np.float64), seg + 0.5])
    all_line = np.concatenate([line, line[seg]])
    keep = np.concatenate([inside, np.ones(len(seg), dtype=bool)])
    o = np.argsort(key, kind="stable")
    all_line, keep = all_line[o], keep[o]
    brk = np.r_[True, all_line[1:] != all_line[:-1]] | ~keep
    group = np.cumsum(brk)
    sel = o[keep]
    grp = group[keep]
    _, new_line = np.unique(grp, return_inverse=True)
    points = np.concatenate([pts, c_pts])[sel]
    faces_out = np.concatenate([face, c_face])[sel].astype(np.int32)
    bary_out = np.concatenate([bary, c_bary])[sel]
    old_line = all_line[keep]
    n_new = int(new_line.max()) + 1 if len(new_line) else 0
    first_old = np.zeros(n_new, dtype=np.int64)
    first_old[new_line[::-1]] = old_line[::-1]
    # a closed line stays closed only when nothing of it was cut away
    clipped = np.zeros(lines.n_lines, dtype=bool)
    clipped[line[~inside]] = True
    still_closed = lines.closed[first_old] & ~clipped[first_old]
    # drop the repeated seam point of closed lines kept whole
    is_seam = np.zeros(len(src) + len(seg), dtype=bool)
    is_seam[:len(src)] = order >= n_pts
    drop = is_seam[sel] & still_closed[new_line]
    out = SurfaceLines(points=points[~drop], face=faces_out[~drop], bary=bary_out[~drop],
                       line=new_line[~drop].astype(np.int32), closed=still_closed)
    return out
