"""Pictures of a simulated print (PNG, matplotlib Agg): CT-like slices and the error map."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from core.figure_style import integer_ticks, legend_outside, style
from core.tolerance import tol
from sim.deposition import Deposit
from sim.metrics import Quality


def _ct_legend() -> list[Patch | Line2D]:
    """Proxy artists naming what the CT slice colours mean."""
    return [
        Patch(facecolor="white", edgecolor="0.3", label="ink (silicone)"),
        Patch(facecolor="black", edgecolor="0.3", label="gel (support bath)"),
        Line2D([], [], color="red", lw=1.0, label="model outline"),
        Line2D([], [], color="tab:blue", marker="s", ls="", ms=4, label="pore (empty inside)"),
    ]


def ct_slices(path: Path, deposit: Deposit, quality: Quality, title: str = "",
              fractions: Sequence[float] = (0.25, 0.5, 0.75)) -> Path:
    """Save horizontal slices (at height fractions of the model) and a vertical XZ slice.

    Ink is white, gel black (like a CT), the model outline red, pores marked blue; a legend
    below the slices names them.
    """
    with style():
        return _ct_slices(path, deposit, quality, title, fractions)


def _ct_slices(path: Path, deposit: Deposit, quality: Quality, title: str,
               fractions: Sequence[float]) -> Path:
    grid = deposit.grid
    fill = np.clip(deposit.fill, 0.0, 1.0)
    zs = np.flatnonzero(quality.inside.any(axis=(0, 1)))
    ys = np.flatnonzero(quality.inside.any(axis=(0, 2)))
    if zs.size == 0:
        zs, ys = np.arange(grid.shape[2]), np.arange(grid.shape[1])
    ks = [int(zs[0] + f * (zs[-1] - zs[0])) for f in fractions]
    j = int(0.5 * (ys[0] + ys[-1]))
    x, y, z = (grid.axis_centers(a) for a in range(3))
    fig, axes = plt.subplots(1, len(ks) + 1, figsize=(4.2 * (len(ks) + 1), 4.4))
    views = [(fill[:, :, k], quality.inside[:, :, k], quality.pores[:, :, k], x, y,
              f"z = {z[k]:.1f} mm", ("x (mm)", "y (mm)")) for k in ks]
    views.append((fill[:, j, :], quality.inside[:, j, :], quality.pores[:, j, :], x, z,
                  f"y = {y[j]:.1f} mm", ("x (mm)", "z (mm)")))
    for ax, (img, ins, por, u, v, label, names) in zip(axes, views, strict=True):
        label = f"slice at {label}"
        ext = (u[0], u[-1], v[0], v[-1])
        ax.imshow(img.T, origin="lower", cmap="gray", vmin=0, vmax=1, extent=ext,
                  interpolation="nearest")
        if ins.any() and not ins.all():
            ax.contour(u, v, ins.T.astype(float), levels=[0.5], colors="red", linewidths=0.8)
        if por.any():
            pu, pv = np.nonzero(por)
            ax.plot(u[pu], v[pv], "s", color="tab:blue", markersize=1.5, alpha=0.7)
        ax.set_title(label)
        ax.set_xlabel(names[0])
        ax.set_ylabel(names[1])
        ax.set_aspect("equal")
        ax.grid(False)
    fig.suptitle(title or "simulated CT slices of the print")
    fig.tight_layout(rect=(0.0, 0.08, 1.0, 1.0))
    fig.legend(handles=_ct_legend(), loc="lower center", ncol=4, bbox_to_anchor=(0.5, 0.0),
               facecolor="0.85")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def error_map(path: Path, quality: Quality, title: str = "", limit_mm: float | None = None,
              max_points: int = 6000) -> Path:
    """Save the signed surface error on the model surface (two 3D views) and its histogram."""
    with style():
        return _error_map(path, quality, title, limit_mm, max_points)


def _error_map(path: Path, quality: Quality, title: str, limit_mm: float | None,
               max_points: int) -> Path:
    pts = quality.surface.map_points
    d = quality.surface.map_distance
    if len(pts) > max_points:  # 3D scatter cost grows with the point count
        pick = np.random.default_rng(0).choice(len(pts), max_points, replace=False)
        pts, d = pts[pick], d[pick]
    finite = np.isfinite(d)
    lim = limit_mm or (float(np.percentile(np.abs(d[finite]), 98)) if finite.any() else 1.0)
    lim = max(lim, 1e-3)
    fig = plt.figure(figsize=(16, 5.2))
    grid = fig.add_gridspec(1, 5, width_ratios=[1.4, 1.4, 0.05, 0.55, 1.1], wspace=0.08,
                            left=0.01, right=0.97, top=0.88, bottom=0.12)
    views = (((25, -60), "seen from above (elevation 25 deg)"),
             ((-25, 120), "seen from below, turned 180 deg"))
    for i, ((elev, azim), name) in enumerate(views):
        ax3 = fig.add_subplot(grid[0, i], projection="3d")
        ax3.set_title(name, fontsize=10)
        sc = ax3.scatter(pts[:, 0], pts[:, 1], pts[:, 2], c=np.clip(d, -lim, lim), s=3,
                         cmap="coolwarm", vmin=-lim, vmax=lim)
        ax3.view_init(elev=elev, azim=azim)
        ax3.set_box_aspect(tuple(np.ptp(pts, axis=0) + tol.floor))
        ax3.set_axis_off()
        _scale_bar(ax3, pts)
    fig.colorbar(sc, cax=fig.add_subplot(grid[0, 2]),
                 label="signed error: printed surface - model (mm)")
    ax = fig.add_subplot(grid[0, 4])
    err = np.abs(quality.surface.distance)
    if err.size:
        ax.hist(err, bins=60, color="tab:gray")
    s = quality.surface.stats()
    facing = quality.surface.by_facing()
    signed = "  ".join(f"{name} {part['signed_mean']:+.3f}" for name, part in facing.items()
                        if part["share"] > 0)
    ax.set_title(f"|error| mean {s['mean']:.3f}  p95 {s['p95']:.3f}  max {s['max']:.3f} mm"
                 + (f"\nsigned by facing: {signed} mm" if signed else ""), fontsize=10)
    ax.set_xlabel("distance of printed surface to model (mm)")
    ax.set_ylabel("surface samples")
    fig.suptitle(title or "surface error on the model (red: ink outside, blue: short)")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def _scale_bar(ax3: Any, pts: np.ndarray) -> None:
    """A labelled 10 mm-class bar along x at the lowest corner of the points (mm)."""
    span = float(np.ptp(pts[:, 0])) if len(pts) else 0.0
    if span <= 0:
        return
    length = float(10 ** np.floor(np.log10(span / 2)))
    lo = pts.min(axis=0)
    ax3.plot([lo[0], lo[0] + length], [lo[1], lo[1]], [lo[2], lo[2]], "k-", lw=2)
    ax3.text(lo[0], lo[1], lo[2], f"{length:g} mm", fontsize=8)


def layer_plot(path: Path, quality: Quality, baseline: Quality | None = None,
               labels: tuple[str, str] = ("multi-axis", "planar")) -> Path:
    """Save over/under-deposition per layer (and of a baseline, if given)."""
    with style():
        return _layer_plot(path, quality, baseline, labels)


def _layer_plot(path: Path, quality: Quality, baseline: Quality | None,
                labels: tuple[str, str]) -> Path:
    fig, ax = plt.subplots(figsize=(9, 4))
    for q, name, line in ((quality, labels[0], "-"), (baseline, labels[1], "--")):
        if q is None or q.layers is None or q.layers.layer.size == 0:
            continue
        under, over = q.layers.ratios()
        ax.plot(q.layers.layer, 100 * over, line, color="tab:red", label=f"{name} over")
        ax.plot(q.layers.layer, 100 * under, line, color="tab:blue", label=f"{name} under")
    ax.set_xlabel("layer")
    ax.set_ylabel("% of the layer's model volume")
    integer_ticks(ax)
    if ax.get_legend_handles_labels()[0]:
        legend_outside(ax)
    ax.set_title("over- and under-deposition per layer")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def slowdown_plot(path: Path, layer: np.ndarray, length_mm: np.ndarray, ratio: np.ndarray,
                  extra_mm3: np.ndarray, slowed: float, synced: bool = False) -> Path:
    """Save, per layer, the share of the extruding path the planned trajectory moves slower
    than ``slowed`` x its toolpath speed, and the extra ink that lands there.

    layer, length_mm, ratio, extra_mm3: (S,) per extruding segment: layer, mm, planned over
    toolpath speed, mm^3 deposited beyond the toolpath's (C * dt - C * L / v).
    synced: the simulated extruder follows the planned speed (else it holds the rate C); the
    title says which.
    """
    with style():
        return _slowdown_plot(path, layer, length_mm, ratio, extra_mm3, slowed, synced)


def _slowdown_plot(path: Path, layer: np.ndarray, length_mm: np.ndarray, ratio: np.ndarray,
                   extra_mm3: np.ndarray, slowed: float, synced: bool) -> Path:
    fig, ax = plt.subplots(figsize=(9.5, 4.2))
    layers = np.unique(layer)
    if layers.size:
        idx = np.searchsorted(layers, layer)
        total = np.bincount(idx, weights=length_mm, minlength=layers.size)
        slow = np.bincount(idx, weights=np.where(ratio < slowed, length_mm, 0.0),
                           minlength=layers.size)
        extra = np.bincount(idx, weights=extra_mm3, minlength=layers.size)
        ax.bar(layers, 100 * slow / np.maximum(total, tol.zero), color="tab:orange",
               label=f"path below {100 * slowed:.0f} % of its speed")
        twin = ax.twinx()
        twin.grid(False)
        twin.plot(layers, extra, ".-", color="tab:red", lw=0.8, label="extra ink (mm$^3$)")
        twin.set_ylabel("extra ink (mm$^3$)", color="tab:red")
    ax.set_xlabel("layer")
    ax.set_ylabel("% of the layer's extruding path")
    integer_ticks(ax)
    handles = [h for a in fig.axes for h in a.get_legend_handles_labels()[0]]
    if handles:
        ax.legend(handles, [str(h.get_label()) for h in handles], loc="upper center",
                  bbox_to_anchor=(0.5, -0.15), ncol=2, borderaxespad=0.0)
    ax.set_title("as planned: where the arm slows down; extruder rate "
                 + ("follows the arm (synced flow)" if synced else "held at C (constant flow)"))
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
