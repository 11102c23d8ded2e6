"""Pinholes: a hole far narrower than a line is closed (consistently wound, no new vertex),
a real hole and a small island are kept, and a dome cap with a pinhole prints as the cap."""

from __future__ import annotations

import numpy as np
import pytest

from core.stages import Layers
from slicer.config import JobConfig
from slicer.extrusion import load_profile
from slicer.toolpath import pinholes
from slicer.toolpath.build import compute_toolpath
from slicer.toolpath.pinholes import pinhole_fill
from slicer.toolpath.surface import boundary_loops
from tests.slicer.toolpath.pattern_meshes import disc, dome

PROFILE = load_profile("ecoflex-0030")
W = 2.3  # mm, about the line width at H 0.6 mm


def pinholed(radius: float = 8.0, at: tuple[float, float] = (3.0, 2.0), shrink: float = 0.1
             ) -> tuple[np.ndarray, np.ndarray]:
    """A flat disc (edge 0.5 mm) whose triangle nearest ``at`` is shrunk about its centre
    to ``shrink`` of its size and removed: a hole of three edges about 0.15 mm long in all,
    as a cut through a tet mesh can leave."""
    v, f = disc(radius, 0.5)
    centre = v[f].mean(axis=1)
    k = int(np.argmin(np.linalg.norm(centre[:, :2] - at, axis=1)))
    v = v.copy()
    v[f[k]] = centre[k] + shrink * (v[f[k]] - centre[k])
    return v, np.delete(f, k, axis=0)


def directed_edges(f: np.ndarray) -> np.ndarray:
    return np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])


def test_a_pinhole_is_closed_and_wound_with_the_surface() -> None:
    v, f = pinholed()
    assert len(boundary_loops(f)) == 2
    fill = pinhole_fill(v, f, np.full(len(v), W))
    closed = np.concatenate([f, fill])
    assert len(fill) == 1 and len(boundary_loops(closed)) == 1
    # every directed edge once: the fill is wound like its neighbours
    e = directed_edges(closed)
    assert len(np.unique(e, axis=0)) == len(e)


def test_a_real_hole_and_a_small_island_are_kept() -> None:
    """A hole 2 mm round (perimeter 6.3 mm, 2.7 W) is a hole to print around; a separate
    tiny component has one loop, its rim, and is no hole of anything."""
    v, f = disc(8.0, 0.5, inner=1.0)
    assert len(pinhole_fill(v, f, np.full(len(v), W))) == 0
    tiny = np.array([[20.0, 0.0, 0.0], [20.1, 0.0, 0.0], [20.0, 0.1, 0.0]])
    v2 = np.concatenate([v, tiny])
    f2 = np.concatenate([f, [[len(v), len(v) + 1, len(v) + 2]]]).astype(np.int32)
    assert len(pinhole_fill(v2, f2, np.full(len(v2), W))) == 0


def _cap_layer(v: np.ndarray, f: np.ndarray) -> tuple[float, float, float]:
    """Contour width error p50, p90 and volume error of one dome cap layer (H 0.6 mm)."""
    lifted = dome(v, 3.0, 9.0)
    layers = Layers(lifted, f, np.zeros(len(f), np.int32), np.full(len(v), 0.6),
                    np.tile([0.0, 0.0, 1.0], (len(v), 1)))
    res = compute_toolpath(layers, JobConfig(), PROFILE, measure_baselines=False, workers=1)
    err = res.report["width_error"]["contour"]
    return float(err["p50"]), float(err["p90"]), float(res.report["layer_volume_error"])


@pytest.mark.parametrize("closed", [True, False])
def test_a_dome_cap_with_a_pinhole_prints_as_the_cap(closed: bool,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """A dome cap 16 mm across with a 0.15 mm hole 3.6 mm off its centre (suzanne's top
    layer): as a second boundary loop the hole made the cap a band between its rim and the
    hole, the lines fitted across it as across a ring's wall (suzanne's layer 28: 52 % off
    at the median). Closed, the cap prints as the cap without the hole does; kept open
    (the check that the fixture reproduces the failure), it does not."""
    if not closed:
        monkeypatch.setattr(pinholes, "PINHOLE", 0.0)
    p50, p90, volume = _cap_layer(*pinholed())
    p50_0, p90_0, _ = _cap_layer(*disc(8.0, 0.5))
    same = p90 <= p90_0 + 0.02 and p50 <= p50_0 + 0.02
    assert same is closed
    if closed:
        assert p90 <= 0.10 and abs(volume) <= 0.01
