"""Heat-method boundary distance (slicer.toolpath.geodesic)."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import InputError
from slicer.toolpath import geodesic
from tests.slicer.toolpath.pattern_meshes import disc, sliver_disc


@pytest.mark.parametrize("backend", ["heat", "potpourri3d", "igl", "fmm"])
def test_annulus_distance_from_both_loops(backend: str) -> None:
    v, f = disc(20.0, 0.7, inner=8.0, jitter=0.2)
    d = geodesic.boundary_distance(v, f, backend=backend)  # type: ignore[arg-type]
    r = np.linalg.norm(v[:, :2], axis=1)
    exact = np.minimum(20.0 - r, r - 8.0)
    assert d.min() == 0.0
    assert np.abs(d - exact).max() < 0.6
    # the slope (what sets contour spacing) is right away from the ridge
    band = (r > 9.5) & (r < 12.5)
    slope = np.polyfit(r[band], d[band], 1)[0]
    assert slope == pytest.approx(1.0, abs=0.03)


def test_dirichlet_heat_has_no_offset_at_either_loop() -> None:
    v, f = disc(20.0, 0.6, inner=8.0, jitter=0.2)
    d = geodesic.boundary_distance(v, f)
    r = np.linalg.norm(v[:, :2], axis=1)
    err = d - np.minimum(20.0 - r, r - 8.0)
    for band in ((r > 9.0) & (r < 11.0), (r > 17.0) & (r < 19.0)):
        assert abs(err[band].mean()) < 0.06


def test_slivers_do_not_break_the_distance() -> None:
    v, f = sliver_disc(15.0, 0.8)
    d = geodesic.boundary_distance(v, f)
    exact = 15.0 - np.linalg.norm(v[:, :2], axis=1)
    assert np.all(np.isfinite(d))
    assert np.abs(d - exact).max() < 0.8


def test_closed_surface_is_rejected() -> None:
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    f = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    with pytest.raises(InputError):
        geodesic.boundary_distance(v, f)


def test_far_from_the_boundary_the_distance_keeps_growing() -> None:
    # 27 edge lengths from the boundary the heat has decayed to ~1e-12: directions must survive
    v, f = disc(40.0, 1.5)
    d = geodesic.boundary_distance(v, f)
    exact = 40.0 - np.linalg.norm(v[:, :2], axis=1)
    assert np.abs(d - exact).max() < 0.8
