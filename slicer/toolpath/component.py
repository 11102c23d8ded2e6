"""One layer component on its own vertex numbering with its process fields (H, W, speed,
normals), and the path built from lines found on it: map back, drop short fragments,
resample, order, link, and the process values per waypoint (paper 4.2, eq. 4)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core.path_accel import PathAccel
from core.stages import LayerMesh, Pattern
from core.tolerance import tol
from slicer.config import ToolpathConfig
from slicer.extrusion import ExtrusionProfile
from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.linking import Joiner, Lifter, LinkedPath, link_pieces, mesh_graph
from slicer.toolpath.mapback import (
    face_normals,
    interpolate,
    map_back,
    point_normals,
    vertex_normals,
)
from slicer.toolpath.ordering import line_levels, order_lines
from slicer.toolpath.peaks import add_distance_peaks
from slicer.toolpath.resample import (
    drop_short_lines,
    drop_tiny_loops,
    face_neighbours,
    line_index,
    line_lengths,
    resample_lines,
)
from slicer.toolpath.results import Waypoints
from slicer.toolpath.stripe_joins import RIM_INSET, narrow_joins_indexed
from slicer.toolpath.surface_geometry import CENTRE_WIDTH_SCALE

TINY_LOOP = 2.0  # closed lines shorter than this x W are dropped (a blob, not a loop)

#: (H, v, W, normal) at a path's points: (N,) float64 mm, mm/s, mm and (N, 3) float64
SurfaceValues = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                      NDArray[np.float64]]


def compact(vertices: NDArray[np.float64], faces: NDArray[np.int32]) -> tuple[
    NDArray[np.integer], NDArray[np.int32]
]:
    """The vertices ``faces`` use, and the faces renumbered onto them."""
    used, inverse = np.unique(faces, return_inverse=True)
    return used, inverse.reshape(-1, 3).astype(np.int32)


def mean_width(vertices: NDArray[np.float64], faces: NDArray[np.int32],
               width: NDArray[np.float64]) -> float:
    """Area-weighted mean of W over the surface (W-bar of eq. 14)."""
    tri = vertices[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    total = float(area.sum())
    if total <= tol.zero:
        return float(width.mean())
    return float((area * width[faces].mean(axis=1)).sum() / total)


@dataclass(frozen=True, eq=False)
class Built:
    """A component's path built from one set of lines.

    Attributes:
        lines: the resampled lines on the original layer.
        linked: the lines ordered and joined (points, extrude flags, paths).
        waypoints: the linked points with their process values.
        flow: deposited volume per length over the profile's (``fit_flow``).
        scale: (n,) float64 per-vertex width / W(H) the lines print at (pitch-following
            contours), or None.
    """

    lines: SurfaceLines
    linked: LinkedPath
    waypoints: Waypoints
    flow: float = 1.0
    scale: NDArray[np.float64] | None = None


class Component:
    """One layer component on its own vertex numbering, with its process fields;
    ``accel``: the job's cell's path accelerations (None: the bundled cell's)."""

    def __init__(self, layer: LayerMesh, face_ids: NDArray[np.int64], pattern: int,
                 cfg: ToolpathConfig, profile: ExtrusionProfile,
                 accel: PathAccel | None = None) -> None:
        used, faces = compact(layer.vertices, layer.faces[face_ids])
        vertices = layer.vertices[used]
        height = np.maximum(layer.height[used], 0.0)
        direction = layer.direction[used]
        # a vertex where the boundary distance peaks inside a triangle (a disc's centre):
        # else the innermost lines stop short of it and leave a pocket of gel (peaks.py)
        vertices, split, parent, bary = add_distance_peaks(
            vertices, faces, profile.width(np.maximum(height, profile.layer_height_range[0])))
        if len(parent):
            height = np.concatenate([height, interpolate(height, faces, parent, bary)])
            between = interpolate(direction, faces, parent, bary)
            direction = np.concatenate([direction, between / np.maximum(
                np.linalg.norm(between, axis=1, keepdims=True), tol.zero)])
            faces = split
        self.vertices = vertices
        self.faces = faces
        # H as sliced (for the required volume) and H as printed: raised to the profile's
        # smallest, because W = C / (H v) diverges as H -> 0 where the speed saturates.
        # Above the table H stays: the speed saturates at the slowest, and W = C / (H v)
        # is the pitch that slab needs from that filament (clamping H there too overstated
        # W, up to 8 mm where a 3 mm slab needs lines 4.4 mm apart)
        self.height_sliced = height
        self.height = np.maximum(self.height_sliced, profile.layer_height_range[0])
        self.direction = direction
        self.pattern = pattern
        self.cfg = cfg
        self.profile = profile
        # mm/s^2 and rad/s^2: the speed changes the cell's arm follows (``core.path_accel``)
        accel = accel or PathAccel.bundled()
        self.path_accel, self.turn_accel = accel.accel_mm_s2, accel.turn_rad_s2
        self.width = profile.width(self.height)
        # the profile table's speeds: a width scaled by the speed stays within them
        self.v_lo, self.v_hi = (float(x) for x in profile.speed_for_height(
            np.array(profile.height_range[::-1])))
        self.w_mean = mean_width(self.vertices, faces, self.width)
        self.normals = face_normals(self.vertices, faces, self.direction)
        self.vertex_normals = vertex_normals(self.vertices, faces, self.direction)
        self.graph = mesh_graph(self.vertices, faces)
        self.neighbours = face_neighbours(faces)

    def values_at(self, face: NDArray[np.int32], bary: NDArray[np.float64],
                  scale: NDArray[np.float64] | None = None) -> tuple[
        NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]
    ]:
        """(H, v, W) at surface points: H interpolated, v = f(H / beta), W = C / (H v);
        with ``scale`` ((n,) per vertex) the speed is divided by it, so W is multiplied by
        it (``flowed_speed``)."""
        h = np.maximum(interpolate(self.height, self.faces, face, bary),
                       self.profile.layer_height_range[0])
        v = self.profile.speed_at(h)
        if scale is not None:
            v = self.flowed_speed(v, interpolate(scale, self.faces, face, bary))
        return h, v, self.profile.rate_mm3_s / (h * v)

    def flowed_speed(self, speed: NDArray[np.float64], flow: NDArray[np.float64] | float,
                     nominal: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """Speed of lines printed at ``flow`` x the volume per length of ``speed``: divided
        by ``flow``, never beyond the table's speeds unless it already was; with
        ``nominal`` (the profile's speed at H) the width stays within CENTRE_WIDTH_SCALE of
        W(H) however many scalings compound (a centre line's band width, then the flow fit)."""
        v = speed / flow
        if nominal is not None:
            v = np.clip(v, nominal / CENTRE_WIDTH_SCALE[1], nominal / CENTRE_WIDTH_SCALE[0])
        return np.clip(v, np.minimum(self.v_lo, speed), np.maximum(self.v_hi, speed))

    def build(self, lines_found: SurfaceLines, level_of: NDArray[np.float64] | None,
              spacing: float, start: NDArray[np.float64], lifter: Lifter, lift: float,
              trim_distance: NDArray[np.float64] | None = None, link: bool = True,
              join: float | None = None, scale: NDArray[np.float64] | None = None,
              narrow: bool | None = None) -> Built:
        """Map back, drop short fragments, resample, order, link; values per waypoint.

        Args:
            lines_found: lines on the (deformed) surface.
            level_of: (n,) per-vertex boundary distance ordering contours, None for stripes.
            spacing: line spacing on the surface the lines were found on (its units).
            start: (3,) nozzle position before the component.
            lifter, lift: travel clearance.
            trim_distance: (n,) boundary distance on the lines' surface: open line ends
                closer than spacing / 4 to the boundary are cut back by W / 2.
            link: False stops after resampling (lines only: for width measurements).
            join: connectors up to this x W extrude (default: the config's join_factor).
            scale: (n,) per-vertex factor on W the lines print at (``values_at``), or None.
            narrow: stripes (``trim_distance`` given): joins at half width
                (``stripe_joins``); default: the config's narrow_joins.
        """
        narrow_on = self.cfg.narrow_joins if narrow is None else narrow
        lines = map_back(lines_found, self.vertices, self.faces)
        lines = drop_short_lines(lines, self.cfg.min_path_length_mm)
        _, _, w_pt = self.values_at(lines.face, lines.bary, scale)
        kept = drop_tiny_loops(lines, w_pt, TINY_LOOP)
        if kept is not lines:
            lines = kept
            _, _, w_pt = self.values_at(lines.face, lines.bary, scale)
        trim = None
        if trim_distance is not None and lines.n_lines:
            # An open line ending on the boundary stops half a width inside it (a quarter
            # with ``narrow_joins``: the U-turn prints at half width): the U-turn connector
            # to the next line then runs along the boundary inside the layer, its band
            # ending at the boundary (not half outside it).
            idx = line_index(lines)
            ends = np.stack([idx.start, np.maximum(idx.stop - 1, idx.start)], axis=1)
            d_end = interpolate(trim_distance, self.faces, lines.face[ends.ravel()],
                                lines.bary[ends.ravel()]).reshape(-1, 2)
            # (at most a quarter of the line per end: a short stripe across a narrow band
            # keeps half its length rather than vanishing)
            cap = 0.25 * line_lengths(lines)[:, None]
            inset = RIM_INSET if narrow_on else 0.5
            trim = np.where(d_end < 0.25 * spacing, np.minimum(inset * w_pt[ends], cap), 0.0)
        lines = resample_lines(lines, self.vertices, self.faces, self.cfg.waypoint_spacing * w_pt,
                               neighbours=self.neighbours, trim=trim)
        lines = drop_short_lines(lines, self.cfg.min_path_length_mm)
        if not link:
            empty = link_pieces(lines, [], self.vertices, self.faces, self.graph,
                                np.zeros(0), lifter, lift)
            return Built(lines, empty, self._waypoints(empty, self._surface_values(empty, scale)),
                         scale=scale)
        _, _, w_rs = self.values_at(lines.face, lines.bary, scale)
        level = None
        if level_of is not None:
            level = line_levels(lines, interpolate(level_of, self.faces, lines.face, lines.bary))
        factor = self.cfg.join_factor if join is None else join
        joiner = Joiner(lines, self.vertices, self.faces, self.graph, w_rs, lifter, factor)
        if level is None and lines.n_lines:
            ids = line_index(lines)
            joiner.prefetch(np.concatenate([ids.start, np.maximum(ids.stop - 1, ids.start)]))
        pieces = order_lines(lines, start, level, spacing, factor * w_rs, joiner.can_join,
                             closed_first=self.cfg.stripe_perimeter
                             and self.pattern == Pattern.STRIPE)
        linked = link_pieces(lines, pieces, self.vertices, self.faces, self.graph, w_rs,
                             lifter, lift, factor, joiner,
                             spiral=self.cfg.spiral_rings and level is not None)
        pace = None
        values = self._surface_values(linked, scale)
        if level is None and trim_distance is not None and narrow_on:
            # stripe joins lie half or more over the stripes they join: printed narrow, as
            # fast as the arm follows (the line speed at their ends and the path acceleration)
            on = linked.face >= 0
            linked, pace, old_at = narrow_joins_indexed(
                linked, self.vertices, self.faces, values[1],
                np.where(on[:, None], values[3], 0.0), self.path_accel, self.turn_accel)
            values = self._surface_values(linked, scale, (values, old_at))
        return Built(lines, linked, self._waypoints(linked, values, pace), scale=scale)

    def _surface_values(self, linked: LinkedPath, scale: NDArray[np.float64] | None,
                        known: tuple[SurfaceValues, NDArray[np.int64]] | None = None
                        ) -> SurfaceValues:
        """(H, v, W, normal) at the linked points on the surface (``values_at``,
        ``point_normals``; zero H, v, W and the linked normal elsewhere): (N,) float64 x 3,
        (N, 3) float64. ``known``: the values of an earlier path and the index in this one
        of each of its points (``narrow_joins_indexed``): only the other points are
        computed."""
        n = len(linked.points)
        h, v, w = np.zeros(n), np.zeros(n), np.zeros(n)
        normal = linked.normal.copy()
        todo = linked.face >= 0
        if known is not None:
            old, at = known
            h[at], v[at], w[at] = old[0], old[1], old[2]
            normal[at] = old[3]
            todo[at] = False
        h[todo], v[todo], w[todo] = self.values_at(linked.face[todo], linked.bary[todo], scale)
        normal[todo] = point_normals(self.vertex_normals, self.faces, self.normals,
                                     linked.face[todo], linked.bary[todo])
        return h, v, w, normal

    def _waypoints(self, linked: LinkedPath, values: SurfaceValues,
                   pace: NDArray[np.float64] | None = None) -> Waypoints:
        """Process values at the linked points from their ``_surface_values``; ``pace``
        (N,) float64: the speed over the line speed each point prints at, its width divided
        by it (``stripe_joins``: joins print narrower, down to JOIN_SCALE x the width)."""
        n = len(linked.points)
        h, v, w, normal = (a.copy() for a in values)
        on = linked.face >= 0
        if pace is not None and np.any(pace > 1.0):
            thin = (pace > 1.0) & on
            fast = self.flowed_speed(v[thin], 1.0 / pace[thin], self.profile.speed_at(h[thin]))
            w[thin] *= v[thin] / fast
            v[thin] = fast
        if np.any(~on) and np.any(on):
            # travel points copy the process values of the previous surface point
            src = np.maximum.accumulate(np.where(on, np.arange(n), -1))
            first_on = int(np.argmax(on))
            src = np.where(src < 0, first_on, src)
            h, v, w = h[src], v[src], w[src]
        return Waypoints(linked.points, normal, h, w, v, linked.extrude, linked.path,
                         np.full(n, self.pattern, np.int8))
