"""Ribs on contour layers: one line along each wall too narrow for two (flat fixture)."""

from __future__ import annotations

import numpy as np
import pytest

import slicer.toolpath.candidate_choice as candidate_choice
from slicer.config import JobConfig
from slicer.toolpath.build import compute_toolpath
from slicer.toolpath.coverage import layer_coverage
from tests.slicer.toolpath.pattern_meshes import ribbed_block
from tests.slicer.toolpath.test_build import PROFILE, flat_layer


def test_contour_layer_ribs_get_one_line_each(monkeypatch: pytest.MonkeyPatch) -> None:
    """Ribs 2 mm wide (0.9 W) between six holes beside a solid block 16 mm wide, on a
    contour layer (the octagonal pocket's honeycomb in miniature): contours alone leave the
    ribs between the last holes and the block bare (their ink laid elsewhere: p90 63 %,
    gap/overlap 8.5/4.2 %, on the ribs 8.2/7.2 %); with one line along each rib and
    contours on the block the spacing and the coverage are better (p90 21 %, 6.7/5.3 %, on
    the ribs 1.2/10.5 %: their lines cross at the junctions), every rib gets its line."""
    v, f = ribbed_block()
    layers = flat_layer(v, f, 0.6)
    res = compute_toolpath(layers, JobConfig(), PROFILE, measure_baselines=False, workers=1)
    monkeypatch.setattr(candidate_choice, "WALL_SHARE", 2.0)  # never: contours everywhere
    plain = compute_toolpath(layers, JobConfig(), PROFILE, measure_baselines=False, workers=1)
    assert [s["fallback"] for s in res.layer_stats] == [["ribs"]]
    assert [s["fallback"] for s in plain.layer_stats] != [["ribs"]]
    ribs, rings = res.report["width_error"]["contour"], plain.report["width_error"]["contour"]
    assert ribs["p90"] < 0.3 < rings["p90"]
    cov_ribs = layer_coverage(layers, res.toolpath, max_samples=20_000)
    cov_rings = layer_coverage(layers, plain.toolpath, max_samples=20_000)
    assert max(cov_ribs.gap[0], cov_ribs.overlap[0]) < max(cov_rings.gap[0], cov_rings.overlap[0])
    assert abs(res.report["layer_volume_error"]) < 0.01
    # each rib's middle is printed: the ribs above, between and below the third column of
    # holes (x 18-24 mm, y 1, 8 and 15 mm) and the one between it and the block (x 25 mm)
    tp = res.toolpath
    pos = tp.position[tp.extrude]
    for y in (1.0, 8.0, 15.0):
        on = pos[(pos[:, 0] > 19.0) & (pos[:, 0] < 23.0) & (np.abs(pos[:, 1] - y) < 0.5)]
        assert len(on) and np.all(np.abs(on[:, 1] - y) < 0.3)
    assert np.any((np.abs(pos[:, 0] - 25.0) < 0.3) & (pos[:, 1] > 3.0) & (pos[:, 1] < 6.0))
