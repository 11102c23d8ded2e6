"""Ribs on contour layers: walls too narrow for two lines, beside a wider part.

A component that is all one band narrower than about 1.5 W holds one line along its middle
(``candidate_choice``: the centre line). A component that is only partly such a band (ribs
between holes beside a solid boss: the octagonal pocket's honeycomb) gets contours from its
boundary everywhere: the rings of two holes then meet in a rib a rib's width apart (two
lines where one fits), or the lines fitted to the local width leave the rib bare (the rim's
rings carry its ink). ``ribbed`` gives such a component the same rule a whole band gets:
contours on the wide part and one line along each narrow wall (``LineSource.ribs``), kept
where its lines cover the component better and keep their spacing better as printed.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Protocol

from core.stages import Pattern
from slicer.toolpath.stripe_joins import coverage_miss

if TYPE_CHECKING:
    from slicer.config import ToolpathConfig
    from slicer.toolpath.component import Built, Component
    from slicer.toolpath.line_source import LineSource
    from slicer.toolpath.volume import VolumeMatch


class _Candidates(Protocol):
    """What is used of ``candidate_choice.Candidates`` (which calls ``ribbed``)."""

    @property
    def comp(self) -> Component: ...
    @property
    def cfg(self) -> ToolpathConfig: ...
    @property
    def required(self) -> float: ...

    def run_joined(self, surface: LineSource, used: int) -> VolumeMatch[Built]: ...
    def as_printed(self, m: VolumeMatch[Built]) -> VolumeMatch[Built]: ...
    def p90(self, m: VolumeMatch[Built], junctions: bool = False) -> float: ...


def ribbed(cand: _Candidates, surf: LineSource, match: VolumeMatch[Built], used: int,
           half_width: float, share: float, tolerance: float
           ) -> tuple[LineSource, VolumeMatch[Built]] | None:
    """The lines of a component printed with contours (``used``, band fitting on) with its
    walls narrower than 2 x ``half_width`` x its mean W printed along their middle, where
    those walls make up at least ``share`` of its area and the lines are better than
    ``match`` (the lines chosen so far), both as printed (flow-fitted where the volume is
    missed), on both measures: the larger of the area left bare and covered twice
    (``coverage``, the ground truth: a width error along the lines cannot see a wall left
    without a line) and p90 of the width error as the report measures each (the ribs' lines
    as medial lines meeting at junctions, like a centre line); the volume within
    ``tolerance`` (relative) or ``match``'s error. None where they are not."""
    hw = half_width * cand.comp.w_mean
    if (used != Pattern.CONTOUR or not cand.cfg.fit_bands
            or surf.geometry.narrow_share(hw, share) < share):
        return None
    ribs = replace(surf, wall_half_width=hw)
    alt = cand.run_joined(ribs, Pattern.CONTOUR)
    printed = cand.as_printed(alt)
    volume = float(printed.result.waypoints.deposited().sum())
    if (abs(volume / cand.required - 1.0) <= max(tolerance, abs(match.rel_error))
            and _miss(cand, printed) < _miss(cand, cand.as_printed(match))
            and cand.p90(printed, junctions=True) < cand.p90(cand.as_printed(match))):
        return ribs, alt
    return None


def _miss(cand: _Candidates, m: VolumeMatch[Built]) -> float:
    """The larger of the bare and the twice-covered area fraction of ``m``'s lines on the
    component (``stripe_joins.coverage_miss``)."""
    return coverage_miss(cand.comp.vertices, cand.comp.faces, m.result.waypoints)
