"""Pictures of a slicing result (PNG, matplotlib Agg): a person reads these faster than numbers."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection

from core.figure_style import integer_ticks, legend_below, legend_outside, style, value_limits
from core.stages import Layers
from core.tolerance import tol


def height_histogram(
    initial: np.ndarray, initial_weights: np.ndarray, final: np.ndarray,
    final_weights: np.ndarray, target: float, path: Path
) -> Path:
    """Histogram of layer height on the layers, initial (harmonic) vs final field.

    Args:
        initial: (m0,) float64, mm, layer height per face of the initial field's layers.
        initial_weights: (m0,) float64, mm^2, their areas.
        final: (m,) float64, mm, layer height per face of the final layers.
        final_weights: (m,) float64, mm^2, their areas.
        target: float, mm, target layer height.
        path: output PNG.
    """
    with style():
        return _height_histogram(initial, initial_weights, final, final_weights, target, path)


def _height_histogram(
    initial: np.ndarray, initial_weights: np.ndarray, final: np.ndarray,
    final_weights: np.ndarray, target: float, path: Path
) -> Path:
    fig, ax = plt.subplots(figsize=(8.6, 4.0), dpi=120)

    # Statistics of the true values; the drawing range follows the final field (with room
    # either side), since the harmonic baseline can have a very long tail.
    def std(values: np.ndarray, weights: np.ndarray) -> str:
        if not weights.sum() > 0:
            return "no layers"
        mean = np.average(values, weights=weights)
        return f"std {np.sqrt(np.average((values - mean) ** 2, weights=weights)):.3f} mm"

    shown = final if final_weights.sum() > 0 else initial
    lo, hi = np.percentile(shown, [0.5, 99.5]) if len(shown) else (0.0, 2.0 * target)
    lo, hi = max(0.0, lo - 2.0 * (hi - lo) - 0.1 * target), hi + 2.0 * (hi - lo) + 0.1 * target
    bins = np.linspace(lo, hi, 60)
    for values, weights, name, colour in (
            (initial, initial_weights, "initial (harmonic)", "tab:grey"),
            (final, final_weights, "final", "tab:blue")):
        label = f"{name}: {std(values, weights)}"
        if not weights.sum() > 0:  # a field without layers (a flat harmonic start)
            ax.plot([], [], color=colour, label=label)
            continue
        ax.hist(np.clip(values, lo, hi), bins=bins.tolist(), weights=weights / weights.sum(),
                alpha=0.6, color=colour, label=label)
    ax.axvline(target, color="k", linestyle="--", linewidth=1, label=f"target {target:.2f} mm")
    ax.set_xlabel("layer height H (mm; values outside the axis are drawn at its ends)")
    ax.set_ylabel("fraction of the layer area")
    ax.set_title("Layer height distribution")
    legend_outside(ax)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def convergence(o_align: Sequence[float], height_std: Sequence[float], path: Path) -> Path:
    """O_align and layer-height std per iteration (paper Fig. 4e/f).

    A field that needed no iteration (one value) is drawn as its point with a note saying so,
    not as a lone marker on an empty axis.
    """
    with style():
        fig, ax = plt.subplots(figsize=(7.2, 4.0), dpi=120)
        its = np.arange(len(o_align))
        handles = ax.semilogy(its, np.maximum(np.asarray(o_align, float), tol.tiny), "o-",
                              color="tab:red", label="O_align (alignment objective)")
        ax.set_xlabel("iteration")
        ax.set_ylabel("O_align (dimensionless)", color="tab:red")
        integer_ticks(ax)
        if len(height_std):
            twin = ax.twinx()
            twin.grid(False)
            handles += twin.plot(np.arange(len(height_std)), height_std, "s--",
                                 color="tab:blue", label="layer height std")
            twin.set_ylabel("layer height std (mm)", color="tab:blue")
        if len(o_align) <= 1:
            ax.set_xlim(-1, 1)
            ax.text(0.5, 0.85, "no iteration needed: the initial field was kept",
                    transform=ax.transAxes, ha="center", va="center", color="0.3")
        legend_below(ax, handles)
        ax.set_title(f"Convergence of the field iteration ({max(len(o_align) - 1, 0)} "
                     "iterations)")
        fig.tight_layout()
        fig.savefig(path)
        plt.close(fig)
    return path


def section_view(layers: Layers, path: Path, axis: int = 1) -> Path:
    """Cut every layer with the mid plane normal to ``axis``; segments coloured by height."""
    v = layers.vertices
    faces = layers.faces
    if len(faces) == 0:
        raise ValueError("no layers to draw")
    level = 0.5 * (v[:, axis].min() + v[:, axis].max())
    s = v[faces, axis] - level  # (m, 3) signed distances of the face corners
    # A face crosses the plane where exactly one or two corners lie above it.
    above = s > 0
    crossing = above.any(axis=1) & ~above.all(axis=1)
    f = faces[crossing]
    sf = s[crossing]
    # For each of the three edges, an intersection point exists where the signs differ.
    ends = []
    valid = []
    for a, b in ((0, 1), (1, 2), (2, 0)):
        sa, sb = sf[:, a], sf[:, b]
        hit = (sa > 0) != (sb > 0)
        t = np.where(hit, sa / np.where(hit, sa - sb, 1.0), 0.0)
        p = v[f[:, a]] + t[:, None] * (v[f[:, b]] - v[f[:, a]])
        ends.append(p)
        valid.append(hit)
    ends_arr = np.stack(ends, axis=1)  # (k, 3 edges, 3)
    valid_arr = np.stack(valid, axis=1)  # (k, 3)
    order = np.argsort(~valid_arr, axis=1, kind="stable")[:, :2]
    seg = np.take_along_axis(ends_arr, order[:, :, None], axis=1)  # (k, 2, 3)
    other = [i for i in range(3) if i != axis]
    seg2 = seg[:, :, other]
    colour = layers.vertex_height[f].mean(axis=1)
    with style():
        return _section_figure(seg2, colour, other, axis, level, layers.layer_count, path)


def _section_figure(seg2: np.ndarray, colour: np.ndarray, other: list[int], axis: int,
                    level: float, count: int, path: Path) -> Path:
    """Draw the cut segments (k, 2, 2) mm coloured by H (k,) mm into ``path``."""
    fig, ax = plt.subplots(figsize=(6.0, 6.0), dpi=130)
    lc = LineCollection(list(seg2), array=colour, cmap="viridis", linewidths=0.6)
    lc.set_clim(*value_limits(colour, 0.01))
    ax.add_collection(lc)
    ax.autoscale()
    ax.set_aspect("equal")
    names = "xyz"
    ax.set_xlabel(f"{names[other[0]]} (mm)")
    ax.set_ylabel(f"{names[other[1]]} (mm)")
    ax.set_title(f"Layers cut at {names[axis]} = {level:.1f} mm ({count} layers)")
    fig.colorbar(lc, ax=ax, label="layer height H (mm)", shrink=0.8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path
