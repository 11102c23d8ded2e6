"""The voxel edge of a virtual print: the default, coarsened for models too large for it.

Kept apart from the deposition (and free of its imports) so the command line can show the
default and the budget in its help without loading the simulation.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

DEFAULT_VOXEL_MM = 0.25
# Voxels of the default grid: the socket (137 x 125 x 212 mm) at 0.35 mm, ~40 s and ~4.3 GB.
AUTO_VOXEL_BUDGET = 100_000_000


class Notes(Protocol):
    """Receives lines for the operator (``mesp_cell.console.ConsoleProgress`` is one)."""

    def info(self, text: str) -> None: ...


class NoNotes:
    """Notes that go nowhere (library use without a console)."""

    def info(self, text: str) -> None:
        pass


def auto_voxel(vertices: np.ndarray, notes: Notes) -> float:
    """The default voxel edge (mm), coarsened so the grid over ``vertices`` (V, 3) float64 mm
    stays within ``AUTO_VOXEL_BUDGET`` voxels; a coarsened one is told to ``notes``."""
    extent = np.ptp(vertices, axis=0) + 8.0  # the grid's padding and filament overhang
    need = float(np.prod(extent)) / AUTO_VOXEL_BUDGET
    voxel = max(DEFAULT_VOXEL_MM, float(np.ceil(100.0 * need ** (1.0 / 3.0))) / 100.0)
    if voxel > DEFAULT_VOXEL_MM:
        notes.info(f"note: model is large; using --voxel {voxel:.2f} (pass --voxel to choose)")
    return voxel
