"""The wall finding's rule and its fix, on sampled thickness with known shares."""

from __future__ import annotations

import numpy as np

from planner.preflight_walls import NOTE_SHARE, scale_fix, walls_text
from slicer.wall_thickness import WallThickness


def _walls(thin_share: float, thin: float = 0.5, thick: float = 10.0) -> WallThickness:
    n = 1000
    k = round(thin_share * n)
    return WallThickness(np.r_[np.full(k, thin), np.full(n - k, thick)], 40.0)


def test_a_few_thin_walls_are_fine() -> None:
    ok, text = walls_text(_walls(0.05), 2.0, lambda k: True)
    assert ok and text.startswith("5 % of the standing-wall area is thinner than the "
                                  "narrowest line of 2.00 mm")


def test_a_third_thin_is_said_not_refused() -> None:
    ok, text = walls_text(_walls(0.3), 2.0, lambda k: True)
    assert ok and "over-deposit" in text and "--scale-to" not in text


def test_mostly_thin_walls_get_a_size_that_holds_the_line() -> None:
    walls = _walls(0.8)
    ok, text = walls_text(walls, 2.0, lambda k: True)
    assert not ok and "--scale-to" in text
    size = float(text.split("--scale-to ")[1].split()[0])
    scaled = walls.scaled(size / walls.size_mm)
    assert scaled.share_below(2.0) <= NOTE_SHARE  # the fix, followed, passes the check
    assert walls_text(scaled, 2.0, lambda k: True)[0]
    assert size == scale_fix(walls, 2.0) and size % 5 == 0


def test_no_size_fits_asks_for_thicker_walls() -> None:
    ok, text = walls_text(_walls(0.8), 2.0, lambda k: k < 2.0)
    assert not ok and "thicken the walls to at least 2.00 mm" in text and "--scale-to" not in text


def test_no_standing_walls() -> None:
    ok, text = walls_text(WallThickness(np.zeros(0), 40.0), 2.0, lambda k: True)
    assert ok and text.startswith("no standing walls")
