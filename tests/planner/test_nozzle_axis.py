"""planner.nozzle_axis: the tilt moves alpha one to one, the tool frame is a rotation."""

from __future__ import annotations

import numpy as np

from planner.nozzle_axis import alpha_of, nozzle_axis, tool_rotation
from tests.planner.synthetic import random_frames


def test_axis_and_alpha_are_consistent() -> None:
    rng = np.random.default_rng(0)
    n, t = random_frames(50, seed=0)
    for deg in (-20.0, 0.0, 20.0):
        ax = nozzle_axis(n, t, np.full(50, np.radians(deg)))
        assert np.allclose(np.degrees(alpha_of(ax, t)), 90.0 - deg)
    ax = nozzle_axis(n, t, np.zeros(50))
    assert np.allclose(ax, -n)
    # motion leaving the layer: alpha0 = angle(-n, t) and the tilt shifts it one to one
    climb = (t + 0.3 * n) / np.linalg.norm(t + 0.3 * n, axis=1, keepdims=True)
    a0 = np.degrees(alpha_of(-n, climb))
    ax = nozzle_axis(n, climb, np.full(50, np.radians(10.0)))
    assert np.allclose(np.degrees(alpha_of(ax, climb)), a0 - 10.0)
    R = tool_rotation(ax, rng.uniform(-3, 3, 50))
    assert np.allclose(R @ np.swapaxes(R, 1, 2), np.eye(3), atol=1e-12)
    assert np.allclose(R[:, :, 2], ax)
