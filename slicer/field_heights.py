"""The layer height a slicing field implies per tet, and its volume-weighted statistics.

A field g is sliced at iso-values delta apart, so the layer through a tet is
H = delta / |grad g| thick; delta is chosen so the volume-weighted mean of H is the target
layer height, which lets two fields (G0 and the optimised g) be compared by their std alone.
``HeightStats`` is the record of such statistics, also used for the heights measured on the
extracted layers (``slicer.heights``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.stages import TetMesh
from core.tolerance import tol
from slicer.operators import TetOperators, build_operators

ZERO_GRADIENT = 1e-9  # |grad g| below this times its mean: rounding of a constant (no height)
GRADIENT_FLOOR = 1e-6  # |grad g| below this times its mean counts as this (finite heights)


@dataclass(frozen=True)
class HeightStats:
    """Volume-weighted statistics of the per-tet layer height.

    Attributes (all float, mm): mean, std, min, max, p5, p95.
    """

    mean: float
    std: float
    min: float
    max: float
    p5: float
    p95: float

    @property
    def cv(self) -> float:
        """Coefficient of variation std / mean (dimensionless)."""
        return self.std / self.mean if self.mean > 0 else float("nan")

    def as_dict(self) -> dict[str, float]:
        """The report.json form: {"mean", "std", "min", "max", "p5", "p95"} in mm."""
        return {k: float(getattr(self, k)) for k in ("mean", "std", "min", "max", "p5", "p95")}


def _weighted_quantiles(x: np.ndarray, w: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Quantiles ``q`` of ``x`` weighted by ``w`` (midpoint rule on the cumulative weight)."""
    order = np.argsort(x)
    cw = np.cumsum(w[order])
    cw = (cw - 0.5 * w[order]) / cw[-1]
    return np.interp(q, cw, x[order])


def height_weights(gradient: np.ndarray, volume: np.ndarray) -> np.ndarray:
    """Per-tet weight of the layer-height statistics: the volume, 0 where grad g is zero.

    g is constant on a critical region, so a tet with all four vertices on one region (a flat
    tet along a curved region, common at coarse meshes) has grad g = 0 up to rounding
    (below ``ZERO_GRADIENT`` times the volume-weighted mean |grad g|): it lies inside
    one layer and has no layer height. Weighting it would put a floored, orders-of-magnitude
    too large height into the statistics (docs/benchmarks.md, field). A gradient that is
    merely small still counts.

    Args:
        gradient: (T, 3) float64, per-tet gradient.
        volume: (T,) float64, mm^3.

    Returns:
        (T,) float64, mm^3.
    """
    norm = np.linalg.norm(gradient, axis=1)
    wsum = float(volume.sum())
    mean_norm = float((norm * volume).sum() / wsum) if wsum > 0 else 0.0
    return np.where(norm > ZERO_GRADIENT * mean_norm, volume, 0.0)


def layer_heights(gradient: np.ndarray, volume: np.ndarray,
                  layer_height: float) -> tuple[np.ndarray, float]:
    """Per-tet physical layer height with the iso-spacing scaled to the target mean.

    Args:
        gradient: (T, 3) float64, per-tet field gradient (field units per mm).
        volume: (T,) float64, mm^3, tet volumes (the weights, see ``height_weights``).
        layer_height: float, mm, target weighted mean height.

    Returns:
        (H (T,) float64 mm, delta float in field units): H = delta / |grad g|, where delta is
        chosen so that sum(w * H) / sum(w) = layer_height with w = ``height_weights``.
        |grad g| is floored at GRADIENT_FLOOR times its weighted mean so a flat spot (and a
        tet without layer height, which has no weight) gets a finite height.
    """
    norm = np.linalg.norm(gradient, axis=1)
    w = height_weights(gradient, volume)
    wsum = float(w.sum())
    mean_norm = float((norm * w).sum() / wsum) if wsum > 0 else 0.0
    if mean_norm <= tol.zero:
        return np.full(len(norm), np.inf), float("nan")
    norm = np.maximum(norm, GRADIENT_FLOOR * mean_norm)
    delta = layer_height * wsum / float((w / norm).sum())
    return delta / norm, delta


def stats_of_gradient(gradient: np.ndarray, volume: np.ndarray,
                      layer_height: float) -> HeightStats:
    """Weighted layer-height statistics of a field (same target mean for any field).

    Args:
        gradient: (T, 3) float64, per-tet gradient.
        volume: (T,) float64, mm^3 (weights: ``height_weights``, tets without height skipped).
        layer_height: float, mm, target mean.

    Returns:
        The statistics; the mean equals ``layer_height`` by construction, so std of two
        fields compares like with like.
    """
    h, _ = layer_heights(gradient, volume, layer_height)
    w = height_weights(gradient, volume)
    use = w > 0
    if not np.all(np.isfinite(h)) or not use.any():
        nan = float("nan")
        return HeightStats(nan, nan, nan, nan, nan, nan)
    h, w = h[use], w[use]
    mean = float((h * w).sum() / w.sum())
    std = float(np.sqrt((w * (h - mean) ** 2).sum() / w.sum()))
    p5, p95 = _weighted_quantiles(h, w, np.array([0.05, 0.95]))
    return HeightStats(mean=mean, std=std, min=float(h.min()), max=float(h.max()),
                       p5=float(p5), p95=float(p95))


@dataclass(frozen=True, eq=False)
class HeightDistribution:
    """The per-tet layer height of one field, with its statistics.

    Attributes:
        per_tet: (T,) float64, mm, H = delta / |grad g| per tet.
        volume: (T,) float64, mm^3, the weights of every statistic: tet volumes, 0 for tets
            without a layer height (``height_weights``).
        delta: float, field units, the iso-spacing giving the target mean height.
        stats: the volume-weighted statistics.
    """

    per_tet: np.ndarray
    volume: np.ndarray
    delta: float
    stats: HeightStats

    def summary(self) -> dict[str, float]:
        """{"mean", "std", "min", "max", "p5", "p95"} in mm (report.json's height_mm)."""
        return self.stats.as_dict()


def height_stats(mesh: TetMesh | TetOperators, g: np.ndarray,
                 layer_height: float) -> HeightDistribution:
    """Layer-height distribution of a vertex field on a mesh, scaled to the target mean.

    Use it for G0 and for the final g alike: both get the same mean, so their std compare
    like with like (report.json's height_std_initial_mm vs height_mm.std).

    Args:
        mesh: the tet mesh (or its operators, to skip rebuilding them).
        g: (V,) float64, the field.
        layer_height: float, mm, target volume-weighted mean height.
    """
    ops = mesh if isinstance(mesh, TetOperators) else build_operators(mesh)
    grad = ops.gradient(np.asarray(g, dtype=np.float64))
    h, delta = layer_heights(grad, ops.volume, layer_height)
    return HeightDistribution(per_tet=h, volume=height_weights(grad, ops.volume), delta=delta,
                              stats=stats_of_gradient(grad, ops.volume, layer_height))


def height_std(gradient: np.ndarray, volume: np.ndarray, layer_height: float) -> float:
    """Just the volume-weighted std of ``layer_heights`` (mm), cheap enough per iteration."""
    h, _ = layer_heights(gradient, volume, layer_height)
    w = height_weights(gradient, volume)
    w = w / w.sum()
    mean = float(w @ h)
    return float(np.sqrt(w @ (h - mean) ** 2))
