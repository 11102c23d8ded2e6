"""Features thinner than the narrowest filament: where they are, the ink laid beyond them,
and the model size at which they print.

A line cannot be narrower than ``THINNEST`` x W (the nozzle's fastest speed for the layer
height). A strip narrower than that (a thin shell cut by a layer, a sliver, a small tip)
still gets its line, so its component deposits more than the integral of H over it even
after the flow fit (which stops at that width). Such a component's excess is ink the model
does not hold: a 0.2 mm wall printed by a 1.1 mm filament gets 5.7 x its volume.

Scaling the model by s widens a strip of width w to s w, while W (set by the layer height)
stays: per layer, the component needs s^2 x its volume and its narrowest line lays s x its
ink, and there are s x as many layers, so with q = deposited / required the excess is
``s^2 required (q - s)+`` against a model of s^3 V. ``scale_for`` finds the smallest s at
which the summed excess is within a share of the model volume.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from slicer.toolpath.surface_geometry import CENTRE_WIDTH_SCALE

THINNEST = CENTRE_WIDTH_SCALE[0]  # the narrowest line, x the profile's W(H)
OVER_DEPOSIT = 0.02  # a component laying this much more than it needs (relative) is too thin
EXCESS_LIMIT = 0.01  # excess ink above this share of the model volume: the part is refused
# the suggested size aims at this share, times SIZE_MARGIN: the layers are cut anew at the
# new size, so its strips are no scaled copies of the old ones (a tube lying on its side, its
# wall cut obliquely: at the size predicted for 0.5 % its strips were 10 % thinner than
# scaled, +1.1 %)
SCALE_TARGET = 0.5 * EXCESS_LIMIT
SIZE_MARGIN = 1.15
SCALE_STEP_MM = 5.0  # a suggested size is rounded up to this


class _Lines(Protocol):
    """A component's waypoints (``results.Waypoints``)."""

    @property
    def width(self) -> NDArray[np.float64]: ...

    def deposited(self) -> NDArray[np.float64]: ...


class _Component(Protocol):
    """What is read of a component (``results.ComponentResult``)."""

    @property
    def waypoints(self) -> _Lines: ...
    @property
    def required_mm3(self) -> float: ...
    @property
    def deposited_mm3(self) -> float: ...
    @property
    def error(self) -> str: ...


class _Layer(Protocol):
    """What is read of a layer (``results.LayerResult``)."""

    @property
    def index(self) -> int: ...
    @property
    def components(self) -> Sequence[_Component]: ...


@dataclass(frozen=True)
class ThinFeatures:
    """The components of a toolpath that lay more ink than they need at the narrowest line.

    Attributes:
        layer: (k,) int64, each such component's layer.
        required_mm3: (k,) float64, mm^3, the integral of H over it.
        deposited_mm3: (k,) float64, mm^3, what its lines lay.
        line_mm: (k,) float64, mm, the mean width its lines print at (volume-weighted).
        counted: (k,) float64 in [0, 1], the share of each one's extra ink that lies beyond
            its layer's slab of the solid (``within_slabs``; 1 unless set).
    """

    layer: NDArray[np.int64]
    required_mm3: NDArray[np.float64]
    deposited_mm3: NDArray[np.float64]
    line_mm: NDArray[np.float64]
    counted: NDArray[np.float64] | None = None

    @property
    def extra_mm3(self) -> NDArray[np.float64]:
        """(k,) float64, mm^3, each component's ink beyond what it holds, as counted."""
        extra = self.deposited_mm3 - self.required_mm3
        return extra if self.counted is None else extra * self.counted

    @property
    def excess_mm3(self) -> float:
        """Ink laid beyond what these components hold, mm^3."""
        return float(np.sum(self.extra_mm3))

    def within_slabs(self, layer_deposited: NDArray[np.float64], slab_mm3: NDArray[np.float64]
                     ) -> ThinFeatures:
        """These components with only the extra ink that lies beyond their layer's slab
        counted: a layer whose surface only grazes the top of its slab (a part ending
        mid-slab: slivers where its top pokes through the layer) holds less than its slab
        even with the slivers' ink, and that ink is the slab's. layer_deposited, slab_mm3:
        (L,) mm^3 per layer index (what the whole layer lays; the exact slab volume)."""
        extra = self.deposited_mm3 - self.required_mm3
        raw = np.bincount(self.layer, weights=extra, minlength=len(slab_mm3))
        beyond = np.maximum(np.asarray(layer_deposited) - np.asarray(slab_mm3), 0.0)
        share = np.divide(np.minimum(raw, beyond), raw, out=np.zeros_like(raw), where=raw > 0)
        return ThinFeatures(self.layer, self.required_mm3, self.deposited_mm3, self.line_mm,
                            share[self.layer])

    @property
    def width_mm(self) -> NDArray[np.float64]:
        """(k,) float64, mm, each component's mean width: its line's width x required /
        deposited (what the line would print at if it could be that narrow)."""
        return self.line_mm * self.required_mm3 / np.maximum(self.deposited_mm3, 1e-12)

    def typical_width_mm(self) -> float:
        """The median width of the too-thin components, weighted by their excess ink
        (NaN without any)."""
        return _weighted_median(self.width_mm, self.extra_mm3)

    def typical_line_mm(self) -> float:
        """The median width their lines print at, weighted like ``typical_width_mm``."""
        return _weighted_median(self.line_mm, self.extra_mm3)

    def scale_for(self, model_mm3: float, limit: float = SCALE_TARGET) -> float:
        """The smallest uniform scale s >= 1 of the model at which the excess is at most
        ``limit`` x the model volume (module docstring)."""
        req, q = self.required_mm3, self.deposited_mm3 / np.maximum(self.required_mm3, 1e-12)
        if self.counted is not None:
            req = req * self.counted

        def share(s: float) -> float:
            return float(np.sum(req * np.maximum(q - s, 0.0))) / (s * model_mm3)

        if model_mm3 <= 0 or share(1.0) <= limit:
            return 1.0
        lo, hi = 1.0, float(q[req > 0].max())
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if share(mid) <= limit else (mid, hi)
        return hi

    def summary(self, model_mm3: float, size_mm: float) -> dict[str, Any]:
        """The report's ``toolpath.too_thin`` section: the excess, its share of the model,
        the typical wall and line widths, the layers (each with its excess, mm^3) and the
        size (largest extent, mm) at which the excess falls to SCALE_TARGET."""
        layers = np.unique(self.layer)
        per_layer = np.bincount(np.searchsorted(layers, self.layer),
                                weights=self.extra_mm3, minlength=len(layers))
        keep = per_layer > 0
        share = self.excess_mm3 / model_mm3 if model_mm3 > 0 else 0.0
        scale = self.scale_for(model_mm3)
        return {
            "excess_mm3": self.excess_mm3,
            "excess_share": share,
            "limit": EXCESS_LIMIT,
            "wall_mm": self.typical_width_mm(),
            "line_mm": self.typical_line_mm(),
            "layers": [[int(k), round(float(e), 3)]
                       for k, e in zip(layers[keep], per_layer[keep], strict=True)],
            "components": int(np.sum(self.extra_mm3 > 0)),
            "scale": scale,
            "size_mm": size_mm,
            "fits_at_size_mm": suggested_size(size_mm, scale),
        }


def suggested_size(size_mm: float, scale: float) -> float:
    """``size_mm`` x ``scale`` x SIZE_MARGIN rounded up to SCALE_STEP_MM (``size_mm`` when
    no scaling is needed)."""
    if scale <= 1.0:
        return float(size_mm)
    return float(np.ceil(size_mm * scale * SIZE_MARGIN / SCALE_STEP_MM) * SCALE_STEP_MM)


def thin_features(results: Sequence[_Layer]) -> ThinFeatures:
    """The components of ``results`` that deposit more than OVER_DEPOSIT beyond their
    required volume (their lines at the narrowest width could not be narrower)."""
    rows = [(r.index, c) for r in results for c in r.components
            if not c.error and c.required_mm3 > 0
            and c.deposited_mm3 > (1.0 + OVER_DEPOSIT) * c.required_mm3]
    line = []
    for _, c in rows:
        seg = c.waypoints.deposited()
        w = 0.5 * (c.waypoints.width[1:] + c.waypoints.width[:-1])
        line.append(float(np.sum(seg * w) / max(float(seg.sum()), 1e-12)))
    return ThinFeatures(
        layer=np.array([k for k, _ in rows], dtype=np.int64),
        required_mm3=np.array([c.required_mm3 for _, c in rows], dtype=np.float64),
        deposited_mm3=np.array([c.deposited_mm3 for _, c in rows], dtype=np.float64),
        line_mm=np.array(line, dtype=np.float64),
    )


class ThinWallsError(InputError):
    """A part whose too-thin features would lay more than EXCESS_LIMIT of its volume in
    extra ink. ``section`` is the report's ``toolpath`` section (``too_thin`` marks the
    layers); ``size_mm`` the suggested largest extent; ``bbox_mm`` (3,) the model's box at
    that size; ``model`` the file."""

    def __init__(self, model: str, section: dict[str, Any],
                 bbox_mm: tuple[float, float, float]) -> None:
        thin = section["too_thin"]
        self.section = section
        self.size_mm = float(thin["fits_at_size_mm"])
        grow = self.size_mm / max(max(bbox_mm), 1e-12)
        self.bbox_mm = tuple(float(grow * b) for b in bbox_mm)
        layers = [k for k, _ in thin["layers"]]
        span = f"{layers[0]}-{layers[-1]}" if len(layers) > 1 else f"{layers[0]}"
        super().__init__(
            f"{model} has walls about {thin['wall_mm']:.2f} mm thick at its "
            f"{thin['size_mm']:.0f} mm size, thinner than the narrowest line this profile "
            f"prints ({thin['line_mm']:.2f} mm): {len(layers)} layer(s) ({span}, report.json "
            f"toolpath.too_thin) would lay {100 * thin['excess_share']:+.1f}% of the model's "
            "volume in extra ink",
            self.fix_text(None))

    def fix_text(self, too_big: str | None) -> str:
        """The fix: scale the model up to ``size_mm`` unless ``too_big`` (why that size
        does not fit the cell), or a profile with a finer nozzle; or accept thicker walls."""
        accept = ('or print the walls thicker than the model\'s with [toolpath] thin_walls = '
                  '"thicken" in a --job file')
        finer = ("a profile with a finer nozzle (mesp calibrate, then --job with its [extrusion] "
                 "profile)")
        if too_big is None:
            return (f"scale it up with --scale-to {self.size_mm:.0f} (its thin walls then "
                    f"print within {100 * EXCESS_LIMIT:.0f}% of their volume), or use "
                    f"{finer}, {accept}")
        return (f"at --scale-to {self.size_mm:.0f}, where its walls would print, {too_big}; use "
                f"{finer}, {accept}")

    def with_cell(self, too_big: str | None) -> InputError:
        """The same refusal, its fix checked against the cell (``too_big``: why the
        suggested size does not fit it, or None)."""
        return InputError(self.problem, self.fix_text(too_big))


def _weighted_median(values: NDArray[np.float64], weights: NDArray[np.float64]) -> float:
    """Median of ``values`` weighted by ``weights`` (NaN if empty)."""
    if len(values) == 0:
        return float("nan")
    order = np.argsort(values)
    cum = np.cumsum(np.asarray(weights)[order])
    return float(values[order][np.searchsorted(cum, 0.5 * cum[-1])])
