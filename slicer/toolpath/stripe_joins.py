"""Stripe joins printed at half width, and stripe ends at the rim a quarter width inside it.

The stripe ordering joins line ends into chains (``ordering._order_cover``): U-turns along
the boundary, and inside the layer joins from a stripe that ends at a branch point (or a
converging end cut back) to a neighbour's end. A join's band at the full width lies half
or more on the stripes it joins: a U-turn's chord between two stripe ends half a width
inside the boundary covers the last half width of both stripes again (about W^2 / 2 per
turn), an inside join runs over the stripes beside it. That ink is laid twice, and the
volume match takes it from every line of the layer (spacing tau > 1: a strip along every
stripe stays bare). Joins therefore print at JOIN_SCALE x the width (the nozzle speed sets
it, W = C / (H v)), and an open stripe end at the boundary stops JOIN_SCALE x W / 2 inside
it (``RIM_INSET``), so that the narrow U-turn's band ends at the boundary: the path runs
on without a new extrusion start, and the ink goes to the lines. Where the lines then lie
closer than their width (spots no stripe reaches, e.g. between holes and the edge), the
component is also built with full-width joins and keeps the one whose worse of gap and
overlap (``coverage_miss``) is smaller (``strategy``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from core.stages import Layers, Pattern, Toolpath
from core.tolerance import tol
from slicer.toolpath.coverage import layer_coverage
from slicer.toolpath.layer_nearest import inside_barycentric, nearest_on_layer
from slicer.toolpath.linking import LinkedPath
from slicer.toolpath.results import Waypoints

JOIN_SCALE = 0.5  # width of a join over the width of the lines it joins
RIM_INSET = 0.5 * JOIN_SCALE  # x W: how far inside the boundary an open stripe end stops
JOIN_TAPER = 0.1  # x the join's length: where its narrow part starts and ends
NEAREST_FACES = 8  # candidate faces when locating an added point on the layer


def locate(points: NDArray[np.float64], vertices: NDArray[np.float64],
           faces: NDArray[np.int32]
           ) -> tuple[NDArray[np.float64], NDArray[np.int32], NDArray[np.float64]]:
    """The layer point nearest to each of ``points`` ((P, 3) mm), among the NEAREST_FACES
    faces whose centroids are nearest: (P, 3) mm, its face (P,) and barycentrics (P, 3)."""
    q, nearest = nearest_on_layer(points, vertices, faces, NEAREST_FACES)
    face = nearest.astype(np.int32)
    bary = inside_barycentric(q, vertices, faces, face)
    return np.einsum("pk,pkj->pj", bary, vertices[faces[face]]), face, bary


def narrow_joins(linked: LinkedPath, vertices: NDArray[np.float64], faces: NDArray[np.int32]
                 ) -> tuple[LinkedPath, NDArray[np.bool_]]:
    """``linked`` with a point added just inside each end of every join (a run of
    connector segments, ``LinkedPath.connector_segments``), and the (N',) bool mask of the
    points that print narrow: those added and the join's own points between them. The
    added points lie on the layer (``vertices`` (n, 3) mm, ``faces`` (m, 3)): the point
    nearest to the join's line there, with its face and barycentrics.

    A line end keeps its width, so the line's last segment is not tapered; the join's
    short first and last parts (JOIN_TAPER of its length) taper from the line's width to
    the narrow one.
    """
    n = len(linked.points)
    narrow = np.zeros(n, dtype=bool)
    if n < 2:
        return linked, narrow
    conn = linked.connector_segments()
    edge = np.diff(np.concatenate([[0], conn.astype(np.int8), [0]]))
    first = np.flatnonzero(edge == 1)  # run of connector segments from point first ...
    last = np.flatnonzero(edge == -1)  # ... to point last
    if len(first) == 0:
        return linked, narrow
    p = linked.points
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(step)])
    length = arc[last] - arc[first]
    keep = length > 0
    first, last, length = first[keep], last[keep], length[keep]
    # the added points: JOIN_TAPER of the join's length in from each end, on its first
    # and last segment (at most half of either)
    d_a = np.minimum(JOIN_TAPER * length, 0.5 * step[first])
    d_b = np.minimum(JOIN_TAPER * length, 0.5 * step[last - 1])
    u_a = (p[first + 1] - p[first]) / np.maximum(step[first], 1e-300)[:, None]
    u_b = (p[last] - p[last - 1]) / np.maximum(step[last - 1], 1e-300)[:, None]
    new_a = p[first] + d_a[:, None] * u_a
    new_b = p[last] - d_b[:, None] * u_b
    # inserted after point first and before point last (np.insert keeps the given order
    # for equal positions, so a one-segment join gets a then b)
    where = np.concatenate([first + 1, last])
    order = np.argsort(where, kind="stable")
    where = where[order]
    src = np.concatenate([first, last])[order]  # the line end each added point copies
    added, face, bary = locate(np.concatenate([new_a, new_b])[order], vertices, faces)
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
    # new index of every old point, then the span of each join (its own interior points
    # and the two added ones) is narrow
    shift = np.zeros(n + 1, dtype=np.int64)
    np.add.at(shift, where, 1)
    new_index = np.arange(n) + np.cumsum(shift)[:n]
    mark = np.zeros(len(points) + 1, dtype=np.int64)
    np.add.at(mark, new_index[first] + 1, 1)
    np.add.at(mark, new_index[last], -1)
    narrow_new = np.cumsum(mark)[:-1] > 0
    return out, narrow_new


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
