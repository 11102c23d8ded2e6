"""Layer-height statistics measured on the extracted layers, as they will be printed.

The report's ``slicing.height_mm`` is the distribution of H over the layer surfaces (each
face weighted by its area, its H the mean of its three vertices' ``vertex_height``), not over
the tets: a tet with three vertices on a small critical region has |grad g| near zero and a
per-tet "height" of metres, although no layer passes through it with that height. The
initial (harmonic) field is measured the same way, on its own layers (as many as the final
field has), so ``height_std_initial_mm`` and ``height_mm.std`` compare like with like.
``outside_profile`` counts the layer area whose H the extrusion profile's morphology table
does not cover (the filament there is extrapolated).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.stages import Field, Layers
from slicer.field import FieldResult
from slicer.field_heights import HeightStats
from slicer.layers import iso_surfaces, match_slab_heights


@dataclass(frozen=True, eq=False)
class FaceHeights:
    """H per layer face with its area.

    Attributes:
        height: (m,) float64, mm, mean of the face's three vertex heights.
        area: (m,) float64, mm^2, face area (the statistics' weight).
        layer: (m,) int32, the face's layer.
    """

    height: np.ndarray
    area: np.ndarray
    layer: np.ndarray

    def stats(self) -> HeightStats:
        """Area-weighted statistics (NaN when there is no face with area)."""
        w, h = self.area, self.height
        use = (w > 0) & np.isfinite(h)
        if not use.any():
            nan = float("nan")
            return HeightStats(nan, nan, nan, nan, nan, nan)
        w, h = w[use], h[use]
        mean = float(np.average(h, weights=w))
        std = float(np.sqrt(np.average((h - mean) ** 2, weights=w)))
        order = np.argsort(h)
        cw = np.cumsum(w[order])
        cw = (cw - 0.5 * w[order]) / cw[-1]
        p5, p95 = np.interp([0.05, 0.95], cw, h[order])
        return HeightStats(mean=mean, std=std, min=float(h.min()), max=float(h.max()),
                           p5=float(p5), p95=float(p95))


def face_heights(layers: Layers) -> FaceHeights:
    """Per-face H and area of all layers."""
    faces = np.asarray(layers.faces, dtype=np.int64)
    if len(faces) == 0:
        return FaceHeights(np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.int32))
    tri = np.asarray(layers.vertices)[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    height = np.asarray(layers.vertex_height)[faces].mean(axis=1)
    return FaceHeights(height=height, area=area, layer=np.asarray(layers.face_layer))


def initial_layers(result: FieldResult, layer_count: int) -> Layers:
    """The layers the initial (harmonic) field g0 gives in as many equal slabs of its range as
    the final field has layers, extracted and slab-matched like the final field's (no critical
    anchors: a baseline). The same count, not g0's own spacing for the target height: where
    g0 is nearly flat (a thin plate with one critical face) that spacing asks for millions of
    layers."""
    g0 = np.asarray(result.g0, dtype=np.float64)
    count = max(int(layer_count), 1)
    lo, hi = float(g0.min()), float(g0.max())
    bounds = np.linspace(lo, hi, count + 1)
    field = Field(g=g0, iso=0.5 * (bounds[1:] + bounds[:-1]))
    layers, _, _ = match_slab_heights(iso_surfaces(result.operators, field), result.operators,
                                      field)
    return layers


def outside_profile(heights: FaceHeights, h_min: float, h_max: float) -> dict[str, float]:
    """Layer area whose H lies outside the profile's table [h_min, h_max] mm.

    Returns:
        {"below", "above", "fraction"}: area fractions (0-1) of all layer area, and
        "layers": how many layers have any such face.
    """
    total = float(heights.area.sum())
    if total <= 0:
        return {"below": 0.0, "above": 0.0, "fraction": 0.0, "layers": 0}
    below = heights.height < h_min
    above = heights.height > h_max
    out = below | above
    return {"below": float(heights.area[below].sum() / total),
            "above": float(heights.area[above].sum() / total),
            "fraction": float(heights.area[out].sum() / total),
            "layers": int(np.unique(heights.layer[out]).size)}
