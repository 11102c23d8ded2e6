"""HTML preview: one trace per layer, colourings, layer slider, plotly.js inside the file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from planner.cell import load_cell
from planner.plan import plan
from sim.preview import _decimate, colourings, preview_figure, write_preview
from tests.planner import synthetic


def test_preview_of_a_toolpath_without_a_plan(tmp_path: Path) -> None:
    tp = synthetic.spiral(turns=3.0, radius=10.0, height=3.0, step=1.0)
    fig = preview_figure(tp)
    layers = np.unique(tp.layer)
    assert len(fig.data) == len(layers) + 2  # layers, travel, nozzle axes
    assert [c.name for c in colourings(tp, None)] == ["layer", "width W", "height H", "speed v"]
    menu = fig.layout.updatemenus[0].buttons
    assert len(menu) == 4
    steps = fig.layout.sliders[0].steps
    assert len(steps) == len(layers)
    assert steps[0].args[0]["visible"] == [True] + [False] * (len(layers) - 1)
    out = write_preview(tp, tmp_path / "preview.html")
    html = out.read_text()
    assert "<script src=" not in html  # nothing fetched from a network
    assert len(html) > 3_000_000  # plotly.js is inside


def test_planned_preview_adds_alpha_and_slowdown() -> None:
    tp = synthetic.lines(n_lines=2, length=10.0)
    traj = plan(tp, load_cell()).trajectory
    names = [c.name for c in colourings(tp, traj)]
    assert len(names) == 6 and names[4] == "printing angle alpha"
    slow = colourings(tp, traj)[5]
    assert slow.values.shape == (len(tp),) and slow.values.max() <= 1.0
    assert np.allclose(colourings(tp, traj)[4].values, 90.0, atol=1.0)


@pytest.mark.parametrize("max_points", [10, 1000])
def test_decimation_keeps_path_ends(max_points: int) -> None:
    tp = synthetic.lines(n_lines=3, length=20.0)
    idx = _decimate(tp, max_points)
    starts = np.flatnonzero(np.r_[True, tp.path[1:] != tp.path[:-1]])
    ends = np.r_[starts[1:] - 1, len(tp) - 1]
    assert set(starts) | set(ends) <= set(idx.tolist())
    assert np.all(np.diff(idx) > 0)
    if max_points < len(tp):  # thinned: every k-th waypoint of a path plus its two ends
        stride = -(-len(tp) // max_points)
        assert len(idx) <= len(tp) // stride + 3 * len(starts)
    else:
        assert len(idx) == len(tp)
