"""The supervisor's ETA: from the pace the stream keeps."""

from __future__ import annotations

import pytest

from mesp_cell.nodes.supervisor_node import EtaEstimate


def test_eta_follows_the_measured_pace_not_the_asked_one() -> None:
    # asked: 80x at 2 ms = 40,000 samples/s; kept: 32,000 (a lagging twin)
    eta = EtaEstimate(40_000.0)
    assert eta(0.0, 0, 1_000_000) == pytest.approx(25.0)  # nothing measured yet: nominal
    assert eta(1.0, 32_000, 968_000) == pytest.approx(968_000 / 40_000)  # under 2 s seen
    for t in range(2, 50):
        left = eta(float(t), 32_000 * t, 2_000_000 - 32_000 * t)
    assert left == pytest.approx((2_000_000 - 32_000 * 49) / 32_000)
    # a stall: while no sample advances over the window, the nominal pace stands
    stalled = EtaEstimate(40_000.0)
    for t in range(5):
        left = stalled(float(t), 10, 1000)
    assert left == pytest.approx(1000 / 40_000)
    assert stalled(5.0, 10, -3) == 0.0
