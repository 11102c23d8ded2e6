"""The width error of printed lines: neighbours beside a line, lone lines by their band."""

from __future__ import annotations

import numpy as np

from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.width_measure import measure_width


def _lines(parts: list[np.ndarray]) -> SurfaceLines:
    pts = np.concatenate(parts)
    line = np.repeat(np.arange(len(parts)), [len(p) for p in parts]).astype(np.int32)
    return SurfaceLines(pts, np.zeros(len(pts), np.int32), np.tile([1.0, 0.0, 0.0], (len(pts), 1)),
                        line, np.zeros(len(parts), bool))


def test_a_line_met_end_on_is_no_neighbour() -> None:
    # a wall 2 mm wide (y in [-1, 1]) joining a wall along x = 0 (a T): its line, printed
    # 2 mm wide, fills its wall; the line across its end is no spacing
    x = np.linspace(1.0, 20.0, 39)
    stem = np.column_stack([x, 0 * x, 0 * x])
    y = np.linspace(-10.0, 10.0, 41)
    bar = np.column_stack([0 * y, y, 0 * y])
    lines = _lines([stem, bar])
    a = np.array([[1.0, 1.0, 0.0], [1.0, -1.0, 0.0]])
    b = np.array([[20.0, 1.0, 0.0], [20.0, -1.0, 0.0]])
    measured = measure_width(lines, np.full(len(lines.points), 2.0),
                             np.tile([0.0, 0.0, 1.0], (len(lines.points), 1)), lambda: (a, b))
    on_stem = lines.line[:len(measured.error)] == 0  # every point is measured
    assert len(measured.error) == len(lines.points) - int(np.count_nonzero(lines.line == 1))
    assert np.all(on_stem)
    assert np.allclose(measured.error, 0.0, atol=1e-6)
