"""Volume integrals and the tau bisection."""

from __future__ import annotations

import numpy as np
import pytest

from slicer.toolpath.volume import match_volume, required_volume, segment_volume


def _square(n: int = 6) -> tuple[np.ndarray, np.ndarray]:
    x, y = np.meshgrid(np.linspace(0, 10, n), np.linspace(0, 5, n))
    v = np.column_stack([x.ravel(), y.ravel(), np.zeros(n * n)])
    i = np.arange(n - 1)
    a = (i[:, None] * n + i[None, :]).ravel()
    f = np.concatenate([np.column_stack([a, a + 1, a + n + 1]),
                        np.column_stack([a, a + n + 1, a + n])]).astype(np.int32)
    return v, f


def test_required_volume_analytic() -> None:
    v, f = _square()
    assert required_volume(v, f, np.full(len(v), 0.7)) == pytest.approx(50 * 0.7)
    # linear H is integrated exactly: mean of 0.5 + 0.1 x over x in [0, 10] is 1.0
    assert required_volume(v, f, 0.5 + 0.1 * v[:, 0]) == pytest.approx(50 * 1.0)


def test_segment_volume() -> None:
    p = np.array([[0, 0, 0], [2, 0, 0], [2, 3, 0]], dtype=float)
    vol = segment_volume(p, np.array([1.0, 1.0, 2.0]), np.array([2.0, 2.0, 2.0]),
                         np.array([True, False]))
    assert vol == pytest.approx([4.0, 0.0])
    vol = segment_volume(p, np.array([1.0, 1.0, 2.0]), np.array([2.0, 2.0, 2.0]),
                         np.array([True, True]))
    assert vol[1] == pytest.approx(3 * 1.5 * 2.0)


def test_match_volume_proportional() -> None:
    calls = []

    def evaluate(tau: float) -> tuple[float, float]:
        calls.append(tau)
        return 100.0 / tau, tau

    res = match_volume(evaluate, required=90.0, tolerance=1e-3)
    assert res.status == "converged"
    assert res.tau == pytest.approx(100 / 90, rel=1e-3)
    assert res.result == res.tau
    assert len(res.trace) == len(calls) <= 3
    assert abs(res.rel_error) < 1e-3


def test_match_volume_step_function_keeps_best() -> None:
    # volume jumps in steps of 10 % (a discrete number of lines): tolerance unreachable
    def evaluate(tau: float) -> tuple[float, None]:
        lines = np.floor(20.0 / tau)
        return 5.0 * lines, None

    res = match_volume(evaluate, required=97.0, tolerance=1e-3, max_iterations=40)
    assert res.status in ("stalled", "max_iterations")
    assert abs(res.rel_error) == min(abs(t.rel_error) for t in res.trace)
    assert abs(res.rel_error) <= 0.06


def test_match_volume_nonlinear_monotone() -> None:
    def evaluate(tau: float) -> tuple[float, None]:
        return 50.0 / tau**2 + 20.0, None

    res = match_volume(evaluate, required=60.0, tolerance=1e-4, max_iterations=30)
    assert res.status == "converged"
    assert res.tau == pytest.approx(np.sqrt(50 / 40), rel=1e-3)


def test_match_volume_limit() -> None:
    res = match_volume(lambda t: (10.0 / t, None), required=1000.0, tolerance=1e-3)
    assert res.status == "limit"
    assert res.tau == pytest.approx(0.5)


def test_match_volume_scans_a_bracket_it_cannot_close() -> None:
    # V is not monotone (+8 % below tau 1.005, on target up to 1.04, +4 % up to 1.1) and
    # jumps to -8 % at 1.1 (a line and its connectors vanish): the bisection closes in on
    # the jump and stalls, the scan across the bracket finds the plateau
    def evaluate(tau: float) -> tuple[float, float]:
        if tau < 1.005:
            return 108.0, tau
        if tau <= 1.04:
            return 100.0, tau
        return (104.0 if tau < 1.1 else 92.0), tau

    res = match_volume(evaluate, 100.0, 0.005)
    assert res.status == "converged-scan"
    assert abs(res.rel_error) < 0.005
    assert 1.005 <= res.tau <= 1.04
    assert len(res.trace) > 2
