"""A tip (a disc about one width across) prints one line across it instead of nothing."""

from __future__ import annotations

import numpy as np

from slicer.config import JobConfig
from slicer.extrusion import load_profile
from slicer.toolpath.build import compute_toolpath
from slicer.toolpath.tip_line import TIP_INSET, tip_line
from tests.slicer.toolpath.pattern_meshes import disc
from tests.slicer.toolpath.test_build import flat_layer

PROFILE = load_profile("ecoflex-0030")


def test_the_tip_line_crosses_the_disc_through_its_centre() -> None:
    v, f = disc(1.25, 0.2)
    lines = tip_line(v, f, width=2.5)
    assert lines.n_lines == 1 and len(lines.points) >= 2
    assert np.abs(lines.points[:, 2]).max() < 1e-9  # on the surface
    ends = lines.points[[0, -1]]
    assert np.linalg.norm(ends.mean(axis=0)[:2]) < 0.15  # through the centre
    length = float(np.linalg.norm(ends[1] - ends[0]))
    assert abs(length - (1.0 - 2 * TIP_INSET) * 2.5) < 0.25  # inset by a tenth at each end


def test_a_disc_one_width_across_prints_its_volume() -> None:
    """Before: eq. 9's ring inside a 2.5 mm disc is shorter than the shortest path and the
    component printed nothing (the teapot's lid knob: two layers, -100 % each)."""
    w = float(PROFILE.width(np.array([0.6]))[0])
    layers = flat_layer(*disc(0.5 * w, 0.25), 0.6)
    res = compute_toolpath(layers, JobConfig(), PROFILE, measure_baselines=False, workers=1)
    assert res.report["thin_fallback"]["tip"] == 1
    assert abs(res.report["layer_volume_error"]) < 0.03
    ext = res.toolpath.extrude
    assert np.linalg.norm(res.toolpath.position[ext, :2], axis=1).max() < 0.5 * w
