"""slicer.toolpath.stripe_trim: converging stripe ends are cut back, the rest is kept."""

from __future__ import annotations

import numpy as np
import pytest

from slicer.toolpath import stripe_trim
from slicer.toolpath.lines import SurfaceLines


def _polyline(points: list[np.ndarray]) -> SurfaceLines:
    """Straight polylines (face/bary are placeholders: trim_converging only reads points)."""
    pts = np.concatenate(points)
    line = np.concatenate([np.full(len(p), i) for i, p in enumerate(points)]).astype(np.int32)
    bary = np.tile([1.0, 0.0, 0.0], (len(pts), 1))
    return SurfaceLines(pts, np.zeros(len(pts), np.int32), bary, line,
                        np.zeros(len(points), bool))


def test_trim_cuts_a_converging_stripe_where_it_comes_closer_than_the_ratio() -> None:
    # a long line along x and a shorter one that approaches it: y = 2 - x / 10 for x in 0..15
    x = np.linspace(0.0, 20.0, 201)
    long_ = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    xs = np.linspace(0.0, 15.0, 151)
    short = np.column_stack([xs, 2.0 - xs / 10.0, np.zeros_like(xs)])
    far = long_ + np.array([0.0, -2.0, 0.0])  # parallel at the spacing: never cut
    lines = _polyline([long_, short, far])
    out = stripe_trim.trim_converging(lines, 2.0, 0.7)
    assert out.n_lines == 3
    assert np.array_equal(out.points[out.line == 0], long_)
    assert np.array_equal(out.points[out.line == 2], far)
    kept = out.points[out.line == 1]
    # cut where y = 2 - x / 10 reaches 0.7 * 2 = 1.4, i.e. at x = 6 (to the sample spacing)
    assert kept[:, 0].max() == pytest.approx(6.0, abs=0.11)
    assert kept[:, 1].min() >= 1.4 - 1e-9
    assert kept[0, 0] == 0.0  # the far end is untouched


def test_trim_keeps_closed_lines_and_drops_a_stripe_that_is_all_overlap() -> None:
    x = np.linspace(0.0, 10.0, 51)
    base = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    twin = base[5:20] + np.array([0.0, 0.5, 0.0])  # short and 0.25 spacing away everywhere
    lines = _polyline([base, twin])
    out = stripe_trim.trim_converging(lines, 2.0, 0.7)
    assert out.n_lines == 1 and np.array_equal(out.points, base)
    closed = lines._replace(closed=np.array([False, True]))
    assert stripe_trim.trim_converging(closed, 2.0, 0.7).n_lines == 2
