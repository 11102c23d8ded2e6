"""Open line ends carried on to the boundary."""

from __future__ import annotations

import numpy as np

from slicer.toolpath.line_ends import extend_to_boundary
from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.mapback import barycentric
from tests.slicer.toolpath.test_medial import strip


def _line_on(v: np.ndarray, f: np.ndarray, points: np.ndarray, line: np.ndarray
             ) -> SurfaceLines:
    """Points located on the mesh (brute force: the triangle holding each)."""
    face = np.zeros(len(points), np.int32)
    bary = np.zeros((len(points), 3))
    for i, p in enumerate(points):
        b = barycentric(np.repeat(p[None], len(f), 0), v, f, np.arange(len(f), dtype=np.int32))
        k = int(np.argmax(b.min(axis=1)))
        face[i], bary[i] = k, b[k]
    return SurfaceLines(points, face, bary, line.astype(np.int32),
                        np.zeros(int(line.max()) + 1, bool))


def test_an_end_short_of_the_boundary_is_carried_to_it() -> None:
    v, f = strip(20.0, 3.0, 0.5)
    x = np.linspace(1.5, 18.5, 35)
    lines = _line_on(v, f, np.column_stack([x, np.full_like(x, 1.5), 0 * x]), 0 * x)
    out = extend_to_boundary(lines, v, f)
    assert out.points[:, 0].min() < 0.1 and out.points[:, 0].max() > 19.9
    assert np.abs(out.points[:, 1] - 1.5).max() < 1e-6
    assert np.allclose(out.bary.sum(axis=1), 1.0)


def test_an_end_at_another_line_stays() -> None:
    # a line ending 1 mm before a line across the strip (a junction) is not carried over it
    v, f = strip(20.0, 6.0, 0.5)
    x = np.linspace(10.0, 18.5, 18)
    y = np.linspace(0.5, 5.5, 11)
    pts = np.concatenate([np.column_stack([x, np.full_like(x, 3.0), 0 * x]),
                          np.column_stack([np.full_like(y, 9.0), y, 0 * y])])
    lines = _line_on(v, f, pts, np.repeat([0, 1], [len(x), len(y)]))
    out = extend_to_boundary(lines, v, f)
    first = out.points[out.line == 0]
    assert first[:, 0].min() == 10.0  # stays at the junction
    assert first[:, 0].max() > 19.9  # the free end reaches the boundary
