"""Pictures of the toolpath stage (PNG, matplotlib's Agg canvas, no global backend state).

- ``toolpath_layers.png``: a contour layer and the stripe layer above it, projected onto
  their best-fit plane, coloured by the target width W (travel moves dashed grey).
- ``width_error_cdf.png``: cumulative distribution of the measured width error with and
  without the width-driven deformation, contour and stripe layers (paper Figs. 6e, 9f).
- ``stripe_vs_poisson.png``: the same measure for stripes and the real-valued Poisson
  alternative on the stripe layers (paper Fig. 5h).
- ``volume_per_layer.png``: required and deposited volume per layer and the chosen tau.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from core.artifacts import atomic_write_bytes
from core.figure_style import integer_ticks, legend_outside, style, value_limits
from core.stages import Layers, Toolpath

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from slicer.toolpath.results import ToolpathResult


def _figure(width: float, height: float, ncols: int = 1) -> tuple[Figure, list[Axes]]:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=120)
    FigureCanvasAgg(fig)
    axes = [fig.add_subplot(1, ncols, i + 1) for i in range(ncols)]
    return fig, axes


def _save(fig: Figure, path: Path) -> Path:
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png")
    atomic_write_bytes(path, buf.getvalue())
    return path


def _plane_coords(points: NDArray[np.float64]) -> tuple[NDArray[np.float64], tuple[str, str]]:
    """(k, 2) coordinates in the best-fit plane of ``points`` ((k, 3) mm) and axis labels."""
    top = ("model x (mm)", "model y (mm)")
    if len(points) < 3:
        return points[:, :2], top
    centred = points - points.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    if abs(vt[2, 2]) > 0.9:
        return points[:, :2], top  # near-horizontal layer: plain top view in model x, y
    return centred @ vt[:2].T, ("in-layer u (mm, best-fit plane)", "in-layer v (mm)")


def plot_layers(ax_list: list[Axes], toolpath: Toolpath, layer_ids: list[int]) -> None:
    """Draw layers ``layer_ids`` of ``toolpath`` into the given axes, coloured by W."""
    from matplotlib.collections import LineCollection

    vmin, vmax = value_limits(toolpath.width[toolpath.extrude], 0.05)
    for ax, layer in zip(ax_list, layer_ids, strict=False):
        sel = np.flatnonzero(toolpath.layer == layer)
        pos, names = _plane_coords(toolpath.position[sel])
        ext = toolpath.extrude[sel]
        path = toolpath.path[sel]
        same = path[1:] == path[:-1]
        segs = np.stack([pos[:-1], pos[1:]], axis=1)
        dep = same & ext[1:] & ext[:-1]
        trav = same & ~ext[1:] & ~ext[:-1]
        lc = LineCollection(list(segs[dep]), cmap="viridis", linewidths=1.2)
        lc.set_array(0.5 * (toolpath.width[sel][1:] + toolpath.width[sel][:-1])[dep])
        lc.set_clim(vmin, vmax)
        ax.add_collection(lc)
        ax.add_collection(LineCollection(list(segs[trav]), colors="0.6", linewidths=0.6,
                                         linestyles="dashed", label="travel (no ink)"))
        if len(pos):
            ax.set_xlim(pos[:, 0].min() - 1, pos[:, 0].max() + 1)
            ax.set_ylim(pos[:, 1].min() - 1, pos[:, 1].max() + 1)
        ax.set_aspect("equal")
        pattern = "contour" if len(sel) and toolpath.pattern[sel[0]] == 0 else "stripe"
        ax.set_title(f"layer {layer} ({pattern})")
        ax.set_xlabel(names[0])
        ax.set_ylabel(names[1])
        ax.grid(False)
        if trav.any():
            ax.legend(loc="lower left", bbox_to_anchor=(0.0, 1.06), borderaxespad=0.0)
        ax.figure.colorbar(lc, ax=ax, label="toolpath width W (mm)", shrink=0.8)


def _cdf(ax: Axes, values: NDArray[np.float64], label: str, style: str) -> None:
    if values.size == 0:
        return
    x = np.sort(values) * 100.0
    y = np.arange(1, x.size + 1) / x.size
    p90 = float(np.percentile(values, 90)) * 100.0
    ax.plot(x, y, style, label=f"{label} (p90 {p90:.1f} %)")


def _cdf_legend(ax: Axes, empty: str) -> None:
    """The legend of the CDFs drawn on ``ax``, or ``empty`` where there was nothing to draw
    (a job without stripe layers)."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, borderaxespad=0.0)
    else:
        ax.text(50, 0.5, empty, ha="center", va="center", color="0.4")


def write_toolpath_figures(result: ToolpathResult, layers: Layers, out_dir: Path) -> list[Path]:
    """Write the PNGs listed in the module docstring into ``out_dir``; returns their paths."""
    with style():
        return _write(result, layers, out_dir)


def _write(result: ToolpathResult, layers: Layers, out_dir: Path) -> list[Path]:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    tp = result.toolpath
    written: list[Path] = []

    present = np.unique(tp.layer[tp.extrude]) if len(tp) else np.zeros(0, np.int32)
    if present.size:
        mid = int(present[present.size // 2])
        ids = [mid, mid + 1] if mid + 1 in present else ([mid - 1, mid] if mid - 1 in present
                                                          else [mid])
        fig, axes = _figure(6.0 * len(ids), 5.0, len(ids))
        plot_layers(axes, tp, ids)
        written.append(_save(fig, out_dir / "toolpath_layers.png"))

    errs = result.width_errors
    fig, axes = _figure(11.0, 4.5, 2)
    for ax, pattern in zip(axes, ("contour", "stripe"), strict=True):
        e = errs.get(pattern, {})
        _cdf(ax, e.get("deformed", np.zeros(0)), "with deformation", "-")
        _cdf(ax, e.get("undeformed", np.zeros(0)), "without deformation", "--")
        ax.set_title(f"{pattern} layers")
        ax.set_xlabel("width error |spacing - W| / W (%), W the two lines' mean")
        ax.set_ylabel("cumulative probability")
        ax.set_xlim(0, 100)
        ax.set_ylim(0, 1)
        ax.grid(alpha=0.3)
        _cdf_legend(ax, f"no {pattern} layer measured")
    written.append(_save(fig, out_dir / "width_error_cdf.png"))

    fig, axes = _figure(6.0, 4.5)
    ax = axes[0]
    stripe = errs.get("stripe", {})
    _cdf(ax, stripe.get("deformed", np.zeros(0)), "stripe pattern (eq. 11)", "-")
    _cdf(ax, stripe.get("poisson", np.zeros(0)), "Poisson alternative", "--")
    ax.set_xlabel("width error |spacing - W| / W (%), W the two lines' mean")
    ax.set_ylabel("cumulative probability")
    ax.set_xlim(0, 100)
    ax.set_ylim(0, 1)
    ax.grid(alpha=0.3)
    _cdf_legend(ax, "no stripe layer measured")
    ax.set_title("stripe layers: stripes vs Poisson")
    written.append(_save(fig, out_dir / "stripe_vs_poisson.png"))

    stats = result.layer_stats
    if stats:
        fig, axes = _figure(12.5, 4.0, 2)
        idx = np.array([s["layer"] for s in stats])
        axes[0].plot(idx, [s["required_mm3"] for s in stats], "-", label="required (int H dA)")
        axes[0].plot(idx, [s["deposited_mm3"] for s in stats], ".", label="deposited")
        axes[0].set_xlabel("layer")
        axes[0].set_ylabel("volume (mm$^3$)")
        axes[0].set_title("volume per layer")
        legend_outside(axes[0])
        for s in stats:
            axes[1].plot([s["layer"]] * len(s["tau"]), s["tau"], "k.", ms=3)
        axes[1].set_xlabel("layer")
        axes[1].set_ylabel("tau = line spacing / W (dimensionless)")
        axes[1].set_title("chosen spacing factor per path group")
        for ax in axes:
            integer_ticks(ax)
        written.append(_save(fig, out_dir / "volume_per_layer.png"))
    return written
