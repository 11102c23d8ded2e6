"""Interactive offline HTML preview of a job's layers and toolpath (plotly, bundle embedded).

One 3D line trace per layer (the extruding paths, model frame, mm), coloured by a quantity the
menu picks: layer, width W, height H, speed v and, once planned, the printing angle alpha and
the slowdown (planned speed / toolpath speed, ``planner.flow.segment_speeds``). A slider shows
the layers up to the chosen one; the legend toggles the travel moves and the nozzle axes (cones
along -normal at every k-th waypoint, hidden at first). plotly.js is written into the file, so
it opens without a network. Long jobs are decimated along each path to ``max_points``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.artifacts import atomic_write_bytes
from core.stages import Toolpath
from planner.trajectory import Trajectory

MAX_POINTS = 150_000
AXES = 400  # nozzle-axis cones drawn


@dataclass(frozen=True)
class Colouring:
    """One "colour by" choice: a value per waypoint (N,), its colour scale (a plotly name)
    and range (the values' own unless given)."""

    name: str
    unit: str
    values: NDArray[np.float64]
    colorscale: str
    limits: tuple[float, float] | None = None

    def range(self) -> tuple[float, float]:
        """(cmin, cmax) of the colour scale."""
        if self.limits is not None:
            return self.limits
        lo, hi = float(np.min(self.values)), float(np.max(self.values))
        return (lo, hi) if hi > lo else (lo - 0.5, hi + 0.5)

    def scale(self) -> list[list[Any]]:
        """The colour scale as [[position, colour], ...] (what plotly.js takes in a restyle)."""
        from plotly.colors import get_colorscale

        return [list(pair) for pair in get_colorscale(self.colorscale)]


def colourings(toolpath: Toolpath, traj: Trajectory | None) -> list[Colouring]:
    """The quantities the preview can colour by (alpha and slowdown only once planned)."""
    out = [Colouring("layer", "", toolpath.layer.astype(float), "Viridis"),
           Colouring("width W", "mm", toolpath.width, "Plasma"),
           Colouring("height H", "mm", toolpath.height, "Cividis"),
           Colouring("speed v", "mm/s", toolpath.speed, "Turbo")]
    if traj is not None:
        from planner.flow import segment_speeds

        wp = np.asarray(traj.waypoint)
        rows = np.flatnonzero(wp >= 0)
        if len(rows) == len(toolpath):
            alpha = np.asarray(traj.alpha)[rows][np.argsort(wp[rows])]
            out.append(Colouring("printing angle alpha", "deg", alpha, "RdBu", (70.0, 110.0)))
            ratio = np.minimum(segment_speeds(toolpath, traj).ratio, 1.0)
            out.append(Colouring("planned / toolpath speed (1 = not slowed)", "",
                                 np.r_[ratio, ratio[-1:]] if len(ratio) else np.ones(1),
                                 "YlOrRd_r", (0.0, 1.0)))
    return out


def _decimate(toolpath: Toolpath, max_points: int) -> NDArray[np.intp]:
    """Indices of the waypoints drawn: every k-th of each path, path ends kept."""
    n = len(toolpath)
    stride = int(np.ceil(n / max(max_points, 1)))
    if stride <= 1:
        return np.arange(n)
    start = np.r_[True, toolpath.path[1:] != toolpath.path[:-1]]
    first = np.flatnonzero(start)[np.cumsum(start) - 1]
    keep = ((np.arange(n) - first) % stride == 0) | start | np.r_[start[1:], True]
    return np.flatnonzero(keep)


def _polyline(idx: NDArray[np.intp], toolpath: Toolpath, mask: NDArray[np.bool_]
              ) -> NDArray[np.intp]:
    """Waypoint indices (``idx`` where ``mask``) with -1 where a path breaks (a gap)."""
    sel = idx[mask[idx]]
    if len(sel) == 0:
        return sel
    brk = np.r_[False, toolpath.path[sel[1:]] != toolpath.path[sel[:-1]]]
    out = np.insert(sel, np.flatnonzero(brk), -1)
    return out


def _coords(toolpath: Toolpath, line: NDArray[np.intp]) -> list[list[float | None]]:
    """x, y, z lists (None at gaps) rounded to 0.01 mm."""
    pos = np.round(toolpath.position[np.maximum(line, 0)], 2).astype(object)
    pos[line < 0] = None
    return [pos[:, a].tolist() for a in range(3)]


def preview_figure(toolpath: Toolpath, traj: Trajectory | None = None,
                   max_points: int = MAX_POINTS, title: str = "") -> Any:
    """The plotly Figure of the preview (see the module doc)."""
    import plotly.graph_objects as go

    idx = _decimate(toolpath, max_points)
    colours = colourings(toolpath, traj)
    layers = np.unique(toolpath.layer[toolpath.extrude])
    fig = go.Figure()
    lines = []
    for k, layer in enumerate(layers):
        line = _polyline(idx, toolpath, toolpath.extrude & (toolpath.layer == layer))
        lines.append(line)
        x, y, z = _coords(toolpath, line)
        first = colours[0]
        lo, hi = first.range()
        fig.add_trace(go.Scatter3d(
            x=x, y=y, z=z, mode="lines", name=f"layer {int(layer)}", showlegend=False,
            line={"width": 4, "color": _values(first, line), "colorscale": first.scale(),
                  "cmin": lo, "cmax": hi, "showscale": k == 0,
                  "colorbar": {"title": {"text": _label(first)}}},
            hovertemplate=f"layer {int(layer)}<br>%{{x}}, %{{y}}, %{{z}} mm<extra></extra>"))
    travel = _polyline(idx, toolpath, ~toolpath.extrude)
    x, y, z = _coords(toolpath, travel)
    fig.add_trace(go.Scatter3d(x=x, y=y, z=z, mode="lines", name="travel (no ink)",
                               line={"width": 1, "color": "rgba(120,120,120,0.6)",
                                     "dash": "dash"}, visible="legendonly"))
    axes = idx[:: max(1, len(idx) // AXES)]
    p, d = toolpath.position[axes], -toolpath.normal[axes]
    fig.add_trace(go.Cone(x=p[:, 0], y=p[:, 1], z=p[:, 2], u=d[:, 0], v=d[:, 1], w=d[:, 2],
                          sizemode="absolute", sizeref=2.0, anchor="tip", showscale=False,
                          colorscale=[[0, "gray"], [1, "gray"]], name="nozzle axis (-normal)",
                          showlegend=True, visible="legendonly"))
    n_layers = len(layers)
    # array-valued attributes take one entry per trace in a restyle
    menu = [{"label": c.name, "method": "restyle",
             "args": [{"line.color": [_values(c, line) for line in lines],
                       "line.colorscale": [c.scale()] * n_layers, "line.cmin": c.range()[0],
                       "line.cmax": c.range()[1], "line.colorbar.title.text": _label(c)},
                      list(range(n_layers))]}
            for c in colours]
    steps = [{"label": str(int(layer)), "method": "restyle",
              "args": [{"visible": [j <= k for j in range(n_layers)]}, list(range(n_layers))]}
             for k, layer in enumerate(layers)]
    fig.update_layout(
        title=title or f"toolpath: {n_layers} layers, {len(toolpath)} waypoints",
        scene={"aspectmode": "data", "xaxis_title": "x (mm)", "yaxis_title": "y (mm)",
               "zaxis_title": "z (mm)"},
        updatemenus=[{"buttons": menu, "x": 0.0, "y": 1.0, "xanchor": "left",
                      "showactive": True}],
        sliders=[{"steps": steps, "active": max(n_layers - 1, 0),
                  "currentvalue": {"prefix": "layers up to "}, "pad": {"t": 30}}],
        legend={"x": 0.0, "y": 0.9}, margin={"l": 0, "r": 0, "t": 60, "b": 0})
    return fig


def _values(c: Colouring, line: NDArray[np.intp]) -> list[float]:
    v = np.round(c.values[np.maximum(line, 0)], 4)
    return v.tolist()


def _label(c: Colouring) -> str:
    return f"{c.name} ({c.unit})" if c.unit else c.name


def write_preview(toolpath: Toolpath, path: Path, traj: Trajectory | None = None,
                  max_points: int = MAX_POINTS) -> Path:
    """Write the preview as one self-contained HTML file (plotly.js embedded)."""
    fig = preview_figure(toolpath, traj, max_points)
    html = fig.to_html(include_plotlyjs=True, full_html=True)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, html.encode())
    return path
