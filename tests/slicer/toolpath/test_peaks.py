"""Vertices where the boundary distance peaks inside a triangle (slicer/toolpath/peaks.py)."""

from __future__ import annotations

import numpy as np
import pytest

from core.stages import Layers
from slicer.config import JobConfig
from slicer.extrusion import load_profile
from slicer.toolpath import peaks
from slicer.toolpath.build import compute_toolpath
from slicer.toolpath.surface import boundary_edges
from tests.slicer.toolpath.pattern_meshes import disc

PROFILE = load_profile("ecoflex-0030")


def _coarse_disc() -> tuple[np.ndarray, np.ndarray]:
    """A 10 mm disc meshed at 3 mm: no vertex within 1 mm of its centre (as a layer cut
    from a 2-3 mm tet mesh often has)."""
    v, f = disc(10.0, 3.0)
    assert np.linalg.norm(v[:, :2], axis=1).min() > 1.0
    return v, f


def test_a_vertex_is_added_at_the_peak_of_a_coarse_disc() -> None:
    v, f = _coarse_disc()
    width = np.full(len(v), 2.4)
    out_v, out_f, parent, bary = peaks.add_distance_peaks(v, f, width)
    assert len(parent) >= 1
    new = out_v[len(v):]
    assert np.linalg.norm(new[:, :2], axis=1).min() < 1.0  # at the centre, within a mm
    # the new vertex is where it says: in its parent face at its barycentrics
    assert np.allclose(np.einsum("pk,pkj->pj", bary, v[f[parent]]), new)
    assert np.all(bary >= peaks.MIN_BARY - 1e-12)
    # a conforming split: two more faces per new vertex, all still facing +z, the same area
    # and the same boundary
    assert len(out_f) == len(f) + 2 * len(parent)
    def area_z(vv: np.ndarray, ff: np.ndarray) -> np.ndarray:
        p = vv[ff]
        return 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])[:, 2]
    assert np.all(area_z(out_v, out_f) > 0)
    assert area_z(out_v, out_f).sum() == pytest.approx(area_z(v, f).sum())
    assert len(boundary_edges(out_f)) == len(boundary_edges(f))


def test_a_fine_disc_needs_no_peak_vertex() -> None:
    v, f = disc(10.0, 0.5)  # a vertex within 0.5 mm of the centre: the peak is there already
    out_v, out_f, parent, _ = peaks.add_distance_peaks(v, f, np.full(len(v), 2.4))
    assert len(parent) == 0 and out_v is v and out_f is f


def test_the_innermost_loop_of_a_coarse_disc_reaches_its_centre(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Without the peak vertex the boundary distance tops out 1-2 mm short of the radius,
    eq. 9's innermost loop closes that far out and leaves a pocket at the centre. Rings joined
    by connectors (no spiral, whose ridge line reaches the centre either way)."""
    rings = JobConfig().with_overrides(toolpath={"spiral_rings": False})
    v, f = _coarse_disc()
    layers = Layers(v, f, np.zeros(len(f), np.int32), np.full(len(v), 0.6),
                    np.tile([0.0, 0.0, 1.0], (len(v), 1)))
    with_peak = compute_toolpath(layers, rings, PROFILE, measure_baselines=False,
                                 workers=1).toolpath
    monkeypatch.setattr(peaks, "PEAK_GAIN", np.inf)
    without = compute_toolpath(layers, rings, PROFILE, measure_baselines=False,
                               workers=1).toolpath

    def innermost(tp: object) -> float:
        pos = tp.position[tp.extrude]  # type: ignore[attr-defined]
        return float(np.linalg.norm(pos[:, :2], axis=1).min())

    assert innermost(with_peak) < innermost(without) - 0.5
    assert innermost(with_peak) < 2.0
