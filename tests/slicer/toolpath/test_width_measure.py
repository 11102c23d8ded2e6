"""The width error of printed lines: neighbours beside a line, lone lines by their band."""

from __future__ import annotations

import numpy as np
import pytest

from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.width_measure import measure_width


def _lines(parts: list[np.ndarray]) -> SurfaceLines:
    pts = np.concatenate(parts)
    line = np.repeat(np.arange(len(parts)), [len(p) for p in parts]).astype(np.int32)
    return SurfaceLines(pts, np.zeros(len(pts), np.int32), np.tile([1.0, 0.0, 0.0], (len(pts), 1)),
                        line, np.zeros(len(parts), bool))


def test_a_line_met_end_on_is_no_neighbour() -> None:
    # a T of walls 2 mm wide: the stem (y in [-1, 1], x in [1, 20]) joins the bar (x in
    # [-1, 1], y in [-10, 10]); each line, printed 2 mm wide, fills its wall, and the line
    # across the stem's end is no spacing (measured that way: 1-3 mm against 2 mm)
    x = np.linspace(1.0, 19.5, 38)
    y = np.linspace(-9.5, 9.5, 39)
    lines = _lines([np.column_stack([x, 0 * x, 0 * x]), np.column_stack([0 * y, y, 0 * y])])
    corners = np.array([[-1, -10], [1, -10], [1, -1], [20, -1], [20, 1], [1, 1], [1, 10],
                        [-1, 10]], dtype=np.float64)
    a = np.column_stack([corners, np.zeros(len(corners))])
    b = np.roll(a, -1, axis=0)
    measured = measure_width(lines, np.full(len(lines.points), 2.0),
                             np.tile([0.0, 0.0, 1.0], (len(lines.points), 1)), lambda: (a, b),
                             junctions=True)
    assert len(measured.error) == len(lines.points)
    stem = lines.line == 0
    assert np.allclose(measured.error[stem], 0.0, atol=1e-6)
    # the bar's points facing the stem's opening see the corners 1.4 mm away, not the wall
    assert np.percentile(measured.error, 90) < 1e-6
    # without junctions (rings, stripes) the line across is the neighbour, as before
    plain = measure_width(lines, np.full(len(lines.points), 2.0),
                          np.tile([0.0, 0.0, 1.0], (len(lines.points), 1)), lambda: (a, b))
    assert plain.error.max() > 0.4


def test_rings_in_a_wide_area_keep_their_neighbour_at_a_corner() -> None:
    # two square rings 2 mm apart inside a wide area: the outer corner's nearest point on
    # the inner ring is the inner corner, met at 45 deg; it stays the neighbour (a gap of
    # sqrt(2) x 2 mm there, measured), it is not a lone line measured by the area's width
    def square(half: float) -> np.ndarray:
        t = np.linspace(-half, half, 21)[:-1]
        return np.concatenate([np.column_stack([t, -half + 0 * t]),
                               np.column_stack([half + 0 * t, t]),
                               np.column_stack([-t, half + 0 * t]),
                               np.column_stack([-half + 0 * t, -t])])
    rings = [np.column_stack([square(h), np.zeros(80)]) for h in (9.0, 7.0)]
    lines = _lines(rings)._replace(closed=np.ones(2, bool))
    a = np.array([[-40.0, -40.0, 0.0], [40.0, -40.0, 0.0], [40.0, 40.0, 0.0], [-40.0, 40.0, 0.0]])
    measured = measure_width(lines, np.full(len(lines.points), 2.0),
                             np.tile([0.0, 0.0, 1.0], (len(lines.points), 1)),
                             lambda: (a, np.roll(a, -1, axis=0)), junctions=True)
    assert measured.lone == 0
    assert measured.error.max() == pytest.approx(np.sqrt(2.0) - 1.0, abs=0.02)
