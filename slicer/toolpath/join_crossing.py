"""Joins of stripe ends that would lay their connector across another line.

The stripe ordering (``ordering._order_cover``) joins nearby line ends into chains. Where a
stripe ends at a branch point, its nearest free end often lies beyond the stripe that runs
past: a connector there crosses that stripe and covers about W x W twice, and the volume
match spreads every line of the layer to pay for the ink. ``JoinCrossing`` tells such joins
apart so the ordering can leave them out (the two chains then start separately).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from slicer.toolpath.lines import SurfaceLines

CROSS_CLEARANCE = 0.3  # x spacing: a join passing closer than this to another line crosses it
CROSS_SAMPLES = 10  # points tested along the straight chord between the two ends


class JoinCrossing:
    """Whether the chord between two line points passes over a third line.

    The connector follows the chord where it stays on the layer (``linking``), so the
    chord is what is tested: CROSS_SAMPLES points strictly between the ends, each against
    the line points of every line other than the two joined (a line's points lie at most a
    fraction of W apart after resampling, so a crossing leaves a sample within reach).
    """

    def __init__(self, lines: SurfaceLines, spacing: float) -> None:
        self.points: NDArray[np.float64] = lines.points
        self.line: NDArray[np.int32] = lines.line
        self.radius = CROSS_CLEARANCE * spacing
        self.tree = cKDTree(lines.points)

    def crosses(self, a: int, b: int) -> bool:
        """True if the chord from line point ``a`` to ``b`` comes within CROSS_CLEARANCE x
        spacing of a line other than theirs."""
        t = np.linspace(0.0, 1.0, CROSS_SAMPLES + 2)[1:-1, None]
        samples = (1.0 - t) * self.points[a] + t * self.points[b]
        hits = self.tree.query_ball_point(samples, self.radius, return_sorted=False)
        near = np.fromiter((q for h in hits for q in h), dtype=np.int64)
        if near.size == 0:
            return False
        other = self.line[near]
        return bool(np.any((other != self.line[a]) & (other != self.line[b])))
