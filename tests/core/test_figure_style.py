"""The shared figure style: no offset tick labels, readable ranges, legends off the data."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from core.figure_style import legend_outside, style, value_limits
from slicer import figures


def test_nearly_constant_values_get_plain_ticks_and_a_readable_range() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    y = 2.3594 + 1e-6 * np.arange(5)
    with style():
        fig, ax = plt.subplots()
        ax.plot(y, label="H")
        legend = legend_outside(ax)
        fig.canvas.draw()
        assert ax.yaxis.get_major_formatter().get_offset() == ""
        # the legend box lies right of the axes, not over the data
        box = legend.get_window_extent()
        assert box.x0 > ax.get_window_extent().x1
        plt.close(fig)
    lo, hi = value_limits(y, 0.01)
    assert hi - lo == np.float64(0.01) or abs(hi - lo - 0.01) < 1e-12
    assert lo < y.min() and hi > y.max()
    assert value_limits(np.array([1.0, 3.0]), 0.5) == (1.0, 3.0)
    assert value_limits(np.array([np.nan]), 0.5) == (0.0, 0.5)


def test_convergence_of_a_single_value_is_drawn(tmp_path: Path) -> None:
    out = figures.convergence([5.0], [0.2], tmp_path / "c.png")
    assert out.stat().st_size > 5000
