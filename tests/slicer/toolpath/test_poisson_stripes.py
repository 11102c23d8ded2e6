"""slicer.toolpath.poisson_stripes: the potential whose iso-lines are the Poisson alternative."""

from __future__ import annotations

import numpy as np

from slicer.toolpath import poisson_stripes
from tests.slicer.toolpath.pattern_meshes import disc


def test_poisson_potential_recovers_an_integrable_field() -> None:
    v, f = disc(10.0, 1.0, jitter=0.2)
    # lines along y: z = direction^perp = -x... the potential is a linear function of x
    direction = np.tile([0.0, 1.0, 0.0], (len(f), 1))
    phi = poisson_stripes.poisson_potential(v, f, direction)
    a = np.polyfit(v[:, 0], phi, 1)
    assert abs(abs(a[0]) - 1.0) < 1e-6
    assert np.allclose(phi, np.polyval(a, v[:, 0]), atol=1e-6)
