"""The preflight's wall finding: do the part's standing walls hold the narrowest line?

A wall thinner than the narrowest line the toolpath can lay (``thin_features.THINNEST`` x
the profile's width at the job's layer height, paper eq. 4) over-deposits wherever a line
crosses it: `mesp slice` refuses such a part (``slicer.toolpath.thin_features``), and this
says so in seconds. Over half of the standing-wall area thinner than the line is a problem;
its fix is a size at which nine tenths of that area holds the line (rounded up as the
slicer's refusal rounds), checked against the tank, the gel and the accepted model sizes,
or thicker walls where no size fits.
"""

from __future__ import annotations

from collections.abc import Callable

from slicer.toolpath.thin_features import suggested_size
from slicer.wall_thickness import WallThickness

THIN_SHARE = 0.5  # more of the standing-wall area than this thinner than W: a problem
NOTE_SHARE = 0.1  # more than this (and the fix's aim): said, not a problem


def scale_fix(walls: WallThickness, width_mm: float) -> float:
    """A largest extent (mm) at which at most ``NOTE_SHARE`` of the standing-wall area is
    thinner than ``width_mm`` (the slicer's margin and rounding on top)."""
    return suggested_size(walls.size_mm, width_mm / walls.quantile(NOTE_SHARE))


def walls_text(walls: WallThickness, width_mm: float,
               fits: Callable[[float], bool]) -> tuple[bool, str]:
    """(ok, one line) for ``walls`` against lines ``width_mm`` wide; ``fits(k)``: the part
    scaled by ``k`` fits the cell (the suggested size is checked with it)."""
    if not len(walls.thickness):
        return True, "no standing walls: the layers' lines span no wall thickness"
    thin = walls.share_below(width_mm)
    line = f"the narrowest line of {width_mm:.2f} mm"
    if thin <= NOTE_SHARE:
        return True, (f"{100 * thin:.0f} % of the standing-wall area is thinner than {line} "
                      f"(thinnest tenth from {walls.quantile(NOTE_SHARE):.2f} mm)")
    said = (f"{100 * thin:.0f} % of the standing-wall area is thinner than {line} (median "
            f"{walls.quantile(0.5):.2f} mm): lines there over-deposit and leave gaps")
    if thin <= THIN_SHARE:
        return True, said
    target = scale_fix(walls, width_mm)
    if fits(target / walls.size_mm):
        return False, (f"{said}; slice it at --scale-to {target:.0f} (checked: it fits the "
                       f"tank and the gel) or thicken the walls to {width_mm:.2f} mm")
    return False, (f"{said}; no size that fits the cell gives them a line ({target:.0f} mm "
                   f"would): thicken the walls to at least {width_mm:.2f} mm in the model")
