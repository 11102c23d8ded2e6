"""Stripe joins printed narrower, and stripe ends at the rim a quarter width inside it.

The stripe ordering joins line ends into chains (``ordering._order_cover``): U-turns along
the boundary, and inside the layer joins from a stripe that ends at a branch point (or a
converging end cut back) to a neighbour's end. A join's band at the full width lies half
or more on the stripes it joins: a U-turn's chord between two stripe ends half a width
inside the boundary covers the last half width of both stripes again (about W^2 / 2 per
turn), an inside join runs over the stripes beside it. That ink is laid twice, and the
volume match takes it from every line of the layer (spacing tau > 1: a strip along every
stripe stays bare). Joins therefore print at down to JOIN_SCALE x the width (the nozzle
speed sets it, W = C / (H v)): as fast as the arm gets there and back along the join with the
cell's path acceleration (``join_ramp``, ``core.path_accel``: a short join, a U-turn where
the wrist turns with the path, prints wider rather than faster than the arm can follow),
and an open stripe end at the boundary stops JOIN_SCALE x W / 2 inside it (``RIM_INSET``),
so that the narrow U-turn's band ends at the boundary: the path runs
on without a new extrusion start, and the ink goes to the lines. Where the lines then lie
closer than their width (spots no stripe reaches, e.g. between holes and the edge), the
component is also built with full-width joins and keeps the one whose worse of gap and
overlap (``coverage_miss``) is smaller (``strategy``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from core.path_accel import path_accel
from core.stages import Layers, Pattern, Toolpath
from core.tolerance import tol
from slicer.toolpath.coverage import layer_coverage
from slicer.toolpath.layer_nearest import inside_barycentric, nearest_on_layer
from slicer.toolpath.linking import LinkedPath
from slicer.toolpath.results import Waypoints

JOIN_SCALE = 0.5  # width of a join over the width of the lines it joins (at most)
RIM_INSET = 0.5 * JOIN_SCALE  # x W: how far inside the boundary an open stripe end stops
JOIN_TAPER = 0.1  # x the join's length: where its narrow part starts and ends, at least
RAMP_SHARE = 0.45  # x the join's length: the longest speed ramp at either end
NEAREST_FACES = 8  # candidate faces when locating an added point on the layer
# the largest r (r - 1) of a join's peak speed r x the lines' (r = 1 / JOIN_SCALE)
PACE_MAX = (1.0 / JOIN_SCALE) * (1.0 / JOIN_SCALE - 1.0)


class JoinRamp(NamedTuple):
    """How fast a join prints: per join, (J,) float64 each.

    pace: the join's peak speed over the lines' (1 to 1 / JOIN_SCALE): its width is the
        lines' over this (W = C / (H v)).
    ramp_a, ramp_b: mm, the lengths over which the speed rises linearly from the line's
        at the join's start to the peak, and falls from it to the line's at its end.
    """

    pace: NDArray[np.float64]
    ramp_a: NDArray[np.float64]
    ramp_b: NDArray[np.float64]


def join_ramp(length: NDArray[np.float64], v_a: NDArray[np.float64],
              v_b: NDArray[np.float64], accel: NDArray[np.float64] | float) -> JoinRamp:
    """The fastest join an arm with the path acceleration ``accel`` (mm/s^2, per join or
    one for all, ``core.path_accel``) follows: joins of ``length`` (J,) mm between line
    ends printed at ``v_a`` and ``v_b`` (J,) mm/s.

    The speed rises linearly in arc length over ``ramp_a`` from v_a to pace x v_a (and falls
    likewise to v_b): the acceleration v dv/dx is largest at the top, pace (pace - 1) v_a^2
    / ramp_a, and is held to ``accel``. With both ramps at most RAMP_SHARE of the length,
    a short join prints wider and slower than a long one (a join of length L between ends
    at v reaches at most (v + sqrt(v^2 + 4 RAMP_SHARE accel L)) / 2 < sqrt(v^2 + 2
    RAMP_SHARE accel L)); a long one at 1 / JOIN_SCALE x the lines' speed, ramped over at
    least JOIN_TAPER of its length.
    """
    v_top = np.maximum(np.maximum(v_a, v_b), tol.zero)
    g = np.clip(accel * RAMP_SHARE * length / v_top ** 2, 0.0, PACE_MAX)  # pace (pace - 1)
    pace = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * g))
    floor = JOIN_TAPER * length
    ramp_a = np.clip(g * v_a ** 2 / accel, floor, RAMP_SHARE * length)
    ramp_b = np.clip(g * v_b ** 2 / accel, floor, RAMP_SHARE * length)
    return JoinRamp(pace, ramp_a, ramp_b)


def locate(points: NDArray[np.float64], vertices: NDArray[np.float64],
           faces: NDArray[np.int32]
           ) -> tuple[NDArray[np.float64], NDArray[np.int32], NDArray[np.float64]]:
    """The layer point nearest to each of ``points`` ((P, 3) mm), among the NEAREST_FACES
    faces whose centroids are nearest: (P, 3) mm, its face (P,) and barycentrics (P, 3)."""
    q, nearest = nearest_on_layer(points, vertices, faces, NEAREST_FACES)
    face = nearest.astype(np.int32)
    bary = inside_barycentric(q, vertices, faces, face)
    return np.einsum("pk,pkj->pj", bary, vertices[faces[face]]), face, bary


def narrow_joins(linked: LinkedPath, vertices: NDArray[np.float64], faces: NDArray[np.int32],
                 speed: NDArray[np.float64], normal: NDArray[np.float64], accel: float,
                 turn_accel: float) -> tuple[LinkedPath, NDArray[np.float64]]:
    """``linked`` with a point added at the top of each end's speed ramp of every join (a
    run of connector segments, ``LinkedPath.connector_segments``; ``join_ramp``), and the
    (N',) float64 pace of every point: its speed over the line speed there, 1 on the
    lines, rising linearly in arc length along each ramp to the join's pace. ``speed``
    (N,) mm/s is the line speed and ``normal`` (N, 3) the printing direction at each
    point of ``linked`` (zero rows: unknown); ``accel`` mm/s^2 and ``turn_accel`` rad/s^2
    give each join its path acceleration from the turn of the printing direction along it
    (``core.path_accel.path_accel``). The added points lie on the layer (``vertices`` (n, 3)
    mm, ``faces`` (m, 3)): the point nearest to the join's line there, with its face and
    barycentrics. A line end keeps its width, so the line's last segment is not tapered.
    """
    out, pace, _ = narrow_joins_indexed(linked, vertices, faces, speed, normal, accel,
                                        turn_accel)
    return out, pace


def narrow_joins_indexed(linked: LinkedPath, vertices: NDArray[np.float64],
                         faces: NDArray[np.int32], speed: NDArray[np.float64],
                         normal: NDArray[np.float64], accel: float, turn_accel: float
                         ) -> tuple[LinkedPath, NDArray[np.float64], NDArray[np.int64]]:
    """``narrow_joins`` and the (N,) int64 index in the result of every point of ``linked``
    (the others are the added points): values known at the old points need not be
    computed again."""
    n = len(linked.points)
    pace = np.ones(n)
    if n < 2:
        return linked, pace, np.arange(n)
    conn = linked.connector_segments()
    edge = np.diff(np.concatenate([[0], conn.astype(np.int8), [0]]))
    first = np.flatnonzero(edge == 1)  # run of connector segments from point first ...
    last = np.flatnonzero(edge == -1)  # ... to point last
    if len(first) == 0:
        return linked, pace, np.arange(n)
    p = linked.points
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(step)])
    length = arc[last] - arc[first]
    keep = length > 0
    first, last, length = first[keep], last[keep], length[keep]
    # the printing direction's turn per mm along each join: the wrist turns with it
    norm = np.linalg.norm(normal, axis=1)
    nrm = normal / np.maximum(norm, tol.zero)[:, None]
    turn = np.where((norm[1:] > tol.zero) & (norm[:-1] > tol.zero), np.arccos(np.clip(
        np.einsum("ij,ij->i", nrm[1:], nrm[:-1]), -1.0, 1.0)), 0.0)
    turned = np.concatenate([[0.0], np.cumsum(turn)])
    rate = (turned[last] - turned[first]) / length
    ramp = join_ramp(length, speed[first], speed[last], path_accel(rate, accel, turn_accel))
    # the added points: at the top of either ramp, on the segment of the join that holds it
    at_a = arc[first] + ramp.ramp_a
    at_b = arc[last] - ramp.ramp_b
    seg_a = np.clip(np.searchsorted(arc, at_a, side="right") - 1, first, last - 1)
    seg_b = np.clip(np.searchsorted(arc, at_b, side="right") - 1, first, last - 1)
    seg = np.concatenate([seg_a, seg_b])
    along = np.concatenate([at_a, at_b]) - arc[seg]
    u = (p[seg + 1] - p[seg]) / np.maximum(step[seg], tol.tiny)[:, None]
    new = p[seg] + along[:, None] * u
    # inserted after the start of their segment (np.insert keeps the given order for equal
    # positions, so a's come before b's on a shared segment)
    where = seg + 1
    order = np.argsort(where, kind="stable")
    where = where[order]
    src = np.concatenate([first, last])[order]  # the line end each added point copies
    added, face, bary = locate(new[order], vertices, faces)
    points = np.insert(p, where, added, axis=0)
    out = LinkedPath(
        points=points,
        face=np.insert(linked.face, where, face),
        bary=np.insert(linked.bary, where, bary, axis=0),
        normal=np.insert(linked.normal, where, linked.normal[src], axis=0),
        extrude=np.insert(linked.extrude, where, linked.extrude[src]),
        path=np.insert(linked.path, where, linked.path[src]),
        piece=np.insert(linked.piece, where, np.full(len(src), -1, dtype=np.int32)),
    )
    # new index of every old point; each point of a join's span (its ends, interior and
    # added points) gets its join's number, and its pace from its arc length along it
    shift = np.zeros(n + 1, dtype=np.int64)
    np.add.at(shift, where, 1)
    new_index = np.arange(n) + np.cumsum(shift)[:n]
    start, stop = new_index[first], new_index[last]
    mark = np.zeros(len(points) + 1, dtype=np.int64)
    np.add.at(mark, start + 1, 1)
    np.add.at(mark, stop, -1)
    inside = np.cumsum(mark)[:-1] > 0
    join = np.searchsorted(start, np.arange(len(points)), side="right") - 1
    new_arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0),
                                                              axis=1))])
    k = join[inside]
    x = new_arc[inside] - new_arc[start[k]]
    rise = np.minimum(np.minimum(x / ramp.ramp_a[k], (length[k] - x) / ramp.ramp_b[k]), 1.0)
    pace_new = np.ones(len(points))
    pace_new[inside] = 1.0 + (ramp.pace[k] - 1.0) * np.clip(rise, 0.0, 1.0)
    return out, pace_new, new_index


def coverage_miss(vertices: NDArray[np.float64], faces: NDArray[np.int32],
                  waypoints: Waypoints) -> float:
    """The larger of the gap and the overlap (area fractions, ``coverage.layer_coverage``)
    of one component's ``waypoints`` on its surface (``vertices`` (n, 3) mm, ``faces``
    (m, 3)): what decides between narrow and full-width joins where narrow ones leave the
    lines closer than their width."""
    n, m = len(waypoints.position), len(faces)
    if n < 2 or m == 0:
        return 1.0
    surface = Layers(vertices, faces, np.zeros(m, np.int32), np.ones(len(vertices)),
                     np.tile([0.0, 0.0, 1.0], (len(vertices), 1)))
    normal = waypoints.normal / np.maximum(np.linalg.norm(waypoints.normal, axis=1),
                                           tol.zero)[:, None]
    tp = Toolpath(position=waypoints.position, normal=normal, layer=np.zeros(n, np.int32),
                  path=waypoints.path, height=waypoints.height, width=waypoints.width,
                  speed=waypoints.speed, extrude=waypoints.extrude,
                  pattern=np.full(n, Pattern.STRIPE, np.int8))
    cov = layer_coverage(surface, tp)
    return float(max(cov.gap[0], cov.overlap[0]))
