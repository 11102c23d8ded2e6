"""An emulated balance under the emulated extruder's nozzle, with the noise of a real one.

The cup stands on the scale under the nozzle: a reading is the cup's own mass plus what the
plant truly delivered since the cup was placed (``ExtruderPlant.true_volume``, the hidden
truth), times the density, plus Gaussian reading noise, rounded to the scale's resolution.
It answers like ``mesp_cell.scale.SerialScale`` (``grams()``), so calibration cannot tell it
from a balance on a serial line; a tare is one more noisy reading.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from mesp_cell.drivers.extruder_plant import ExtruderPlant


@dataclass(frozen=True)
class ScaleNoise:
    """How the emulated balance reads.

    Attributes:
        sd_g: g, standard deviation of one reading (repeatability of a 1 mg lab balance).
        resolution_g: g, readings are rounded to this.
        cup_g: (lo, hi) g, a fresh cup's mass is uniform in this range.
    """

    sd_g: float = 0.001
    resolution_g: float = 0.001
    cup_g: tuple[float, float] = (2.0, 6.0)

    def __post_init__(self) -> None:
        if self.sd_g < 0 or self.resolution_g < 0 or not 0 <= self.cup_g[0] <= self.cup_g[1]:
            raise ValueError("need sd_g, resolution_g >= 0 and 0 <= cup_g[0] <= cup_g[1]")


class EmulatedScale:
    """See the module docstring. ``density`` in g/cm^3 is the material's true density."""

    def __init__(self, plant: ExtruderPlant, density: float, noise: ScaleNoise | None = None,
                 seed: int | None = None) -> None:
        self.plant = plant
        self.density = float(density)
        self.noise = noise or ScaleNoise()
        self._rng = np.random.default_rng(seed)
        self._cup = 0.0
        self._v0 = 0.0
        self.place_cup()

    def place_cup(self) -> None:
        """A fresh, empty cup under the nozzle."""
        self.plant.step(time.monotonic())
        self._cup = float(self._rng.uniform(*self.noise.cup_g))
        self._v0 = self.plant.true_volume

    def grams(self) -> float:
        """One reading, g: cup + delivered mass + noise, at the scale's resolution."""
        self.plant.step(time.monotonic())
        delivered = (self.plant.true_volume - self._v0) * self.density / 1000.0  # mm^3 -> g
        value = self._cup + delivered + float(self._rng.normal(0.0, self.noise.sd_g))
        res = self.noise.resolution_g
        return round(value / res) * res if res > 0 else value

    def close(self) -> None:
        """Nothing to release (same interface as a serial scale)."""
