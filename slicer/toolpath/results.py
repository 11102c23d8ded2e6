"""The toolpath's result values: waypoints with their process values, and what one
component, one layer and the whole model produced (frozen: built once, then read)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.stages import Pattern, Toolpath
from slicer.status import ToolpathStatus
from slicer.toolpath.linking import deposit_mask
from slicer.toolpath.thin_features import ThinFeatures
from slicer.toolpath.volume import segment_volume

PATTERN_NAMES: dict[int, str] = {Pattern.CONTOUR: "contour", Pattern.STRIPE: "stripe"}


@dataclass(frozen=True, eq=False)
class Waypoints:
    """Waypoints in print order with their process values (one layer or component).

    Attributes:
        position: (N, 3) float64, mm.
        normal: (N, 3) float64, unit.
        height: (N,) float64, mm.
        width: (N,) float64, mm.
        speed: (N,) float64, mm/s.
        extrude: (N,) bool.
        path: (N,) int32, local path id, increasing in print order.
        pattern: (N,) int8, 0 contour, 1 stripe (the pattern the waypoint belongs to).
    """

    position: NDArray[np.float64]
    normal: NDArray[np.float64]
    height: NDArray[np.float64]
    width: NDArray[np.float64]
    speed: NDArray[np.float64]
    extrude: NDArray[np.bool_]
    path: NDArray[np.int32]
    pattern: NDArray[np.int8]

    @staticmethod
    def concat(parts: list[Waypoints]) -> Waypoints:
        """Concatenate, shifting each part's path ids past the previous ones."""
        if not parts:
            return Waypoints(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0),
                             np.zeros(0), np.zeros(0, bool), np.zeros(0, np.int32),
                             np.zeros(0, np.int8))
        offs, paths = 0, []
        for p in parts:
            paths.append(p.path + offs)
            offs += int(p.path.max()) + 1 if len(p.path) else 0
        return Waypoints(
            position=np.concatenate([p.position for p in parts]),
            normal=np.concatenate([p.normal for p in parts]),
            height=np.concatenate([p.height for p in parts]),
            width=np.concatenate([p.width for p in parts]),
            speed=np.concatenate([p.speed for p in parts]),
            extrude=np.concatenate([p.extrude for p in parts]),
            path=np.concatenate(paths).astype(np.int32),
            pattern=np.concatenate([p.pattern for p in parts]).astype(np.int8),
        )

    def deposited(self) -> NDArray[np.float64]:
        """(N - 1,) float64, mm^3, volume of each segment (eq. 2)."""
        return segment_volume(self.position, self.height, self.width,
                              deposit_mask(self.extrude, self.path))


@dataclass(frozen=True, eq=False)
class ComponentResult:
    """One layer component's toolpath and its measurements.

    Attributes:
        waypoints: the component's waypoints (surface and travel).
        pattern: 0 contour, 1 stripe: the pattern used (a stripe layer's component too
            narrow for stripes falls back to contours).
        n_faces: faces of the component.
        required_mm3: integral of H over the component.
        deposited_mm3: deposited volume of the waypoints.
        tau: chosen spacing factor.
        volume_status: status of the bisection; volume_trace: (tau, volume, rel_error) rows.
        deform_status: status of the width deformation ('skipped' when W is constant).
        extrusion_starts: continuous extrusion paths in the component.
        connector_mm3: deposited volume of the connectors that join lines (included in
            deposited_mm3, so the volume match accounts for it).
        width_error: (k,) float64, |spacing - W| / W at the line points (deformed method),
            W the width the waypoints print (after ``fit_flow``, if it scaled the speed),
            the mean of the point's and the neighbouring line's (``_measure``).
        width_error_pointwise: (k,) float64, the same against the point's W alone.
        width_error_nominal: (k,) float64, the same against the profile's W(H).
        width_lone_points: how many of those are on lone lines, measured by their band.
        width_error_undeformed: (k',) float64, same, lines computed on the original layer.
        width_error_poisson: (k'',) float64, Poisson alternative (stripe layers), else empty.
        timings: stage -> s.
        error: why the component was skipped ('' if it was not).
        fallback: '' or how a component too narrow for its pattern was printed instead
            ('contour' on a stripe layer, 'centre-line': one line along the band's middle),
            or 'holes-filled': fitted contours left holes (the component is no band),
            filled with eq. 9's iso-lines.
    """

    waypoints: Waypoints
    pattern: int
    n_faces: int
    required_mm3: float
    deposited_mm3: float
    tau: float
    volume_status: str
    volume_trace: tuple[tuple[float, float, float], ...]
    deform_status: str
    extrusion_starts: int
    connector_mm3: float
    width_error: NDArray[np.float64]
    width_error_undeformed: NDArray[np.float64]
    width_error_poisson: NDArray[np.float64]
    width_error_nominal: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    width_error_pointwise: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    width_lone_points: int = 0
    timings: dict[str, float] = field(default_factory=dict)
    error: str = ""
    fallback: str = ""


@dataclass(frozen=True, eq=False)
class LayerResult:
    """One layer's toolpath.

    Attributes:
        index: layer index.
        pattern: 0 contour, 1 stripe.
        waypoints: all components, joined by travel moves.
        components: per-component results (print order).
        surface_vertices: (n, 3) float64, mm, layer vertices (for travel clearance).
        surface_normals: (n, 3) float64, unit growth direction per vertex.
        lift: float, mm, travel clearance above this layer.
        height_out_of_profile: int, vertices whose H lies outside the profile's table.
        n_vertices: int, vertices of the layer.
    """

    index: int
    pattern: int
    waypoints: Waypoints
    components: list[ComponentResult]
    surface_vertices: NDArray[np.float64]
    surface_normals: NDArray[np.float64]
    lift: float
    height_out_of_profile: int
    n_vertices: int


@dataclass(frozen=True, eq=False)
class ToolpathResult:
    """Output of ``compute_toolpath``.

    Attributes:
        toolpath: the Toolpath stage.
        report: the design.md "toolpath" report section (+ extra keys).
        layer_stats: per-layer dicts (layer, pattern, components, volumes, tau, starts).
        width_errors: {"contour"|"stripe": {"deformed"|"undeformed"|"poisson": (k,) f8}}.
        status: ``ToolpathStatus``: OK; VOLUME when some component missed the volume
            tolerance; FAILED_COMPONENTS when some component was skipped (reasons in the report).
        timings: stage -> s (summed over layers for per-layer stages).
        thin: the components thinner than the narrowest line (``thin_features``).
    """

    toolpath: Toolpath
    report: dict[str, Any]
    layer_stats: list[dict[str, Any]]
    width_errors: dict[str, dict[str, NDArray[np.float64]]]
    status: ToolpathStatus
    timings: dict[str, float]
    thin: ThinFeatures | None = None


def travel_waypoints(points: NDArray[np.float64], normals: NDArray[np.float64],
                     like: Waypoints, at: int) -> Waypoints:
    """Travel waypoints (extrude=False, one path) with the process values of ``like[at]``."""
    k = len(points)
    return Waypoints(
        position=points,
        normal=normals,
        height=np.full(k, like.height[at]),
        width=np.full(k, like.width[at]),
        speed=np.full(k, like.speed[at]),
        extrude=np.zeros(k, dtype=bool),
        path=np.zeros(k, dtype=np.int32),
        pattern=np.full(k, like.pattern[at], np.int8),
    )
