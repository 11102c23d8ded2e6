"""Volume integrals and the tau bisection."""

from __future__ import annotations

import numpy as np
import pytest

from slicer.toolpath.volume import match_volume, required_volume, segment_volume, slab_volumes


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


def _cube_tets() -> tuple[np.ndarray, np.ndarray]:
    """The unit cube as 6 positively oriented tets around the diagonal (0,0,0)-(1,1,1)."""
    v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
    idx = {tuple(p): i for i, p in enumerate(v.astype(int))}
    tets = []
    for perm in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)):
        p = np.zeros(3, dtype=int)
        chain = [idx[tuple(p)]]
        for axis in perm:
            p[axis] = 1
            chain.append(idx[tuple(p)])
        tets.append(chain)
    return v, np.array(tets)


def test_slab_volumes_of_a_linear_field_on_a_cube() -> None:
    v, t = _cube_tets()
    # g = z: slabs of a unit square, thickness = bound spacing; a tie-heavy case (g takes
    # only two values per tet edge direction)
    b = np.array([-1.0, 0.1, 0.35, 0.5, 0.9, 2.0])
    assert np.allclose(slab_volumes(v, t, v[:, 2], b), [0.1, 0.25, 0.15, 0.4, 0.1], atol=1e-7)
    # g = x + y + z: volume below s is s^3 / 6 for s <= 1 (a corner tet), 1/2 at s = 3/2
    g = v.sum(axis=1)
    below = slab_volumes(v, t, g, np.array([0.0, 0.6, 1.0, 1.5, 3.0]))
    assert np.allclose(np.cumsum(below), [0.6**3 / 6, 1 / 6, 0.5, 1.0], atol=1e-7)


def test_slab_volumes_match_sampling_on_a_random_tet() -> None:
    rng = np.random.default_rng(3)
    v = rng.normal(size=(4, 3))
    t = np.array([[0, 1, 2, 3]])
    g = rng.normal(size=4)
    b = np.linspace(g.min() - 0.1, g.max() + 0.1, 7)
    vol = abs(np.linalg.det(v[1:] - v[0])) / 6.0
    exact = slab_volumes(v, t, g, b)
    # points uniform in the tet: barycentric weights ~ Dirichlet(1, 1, 1, 1); g is linear
    w = rng.dirichlet(np.ones(4), 400_000)
    sampled = np.histogram(w @ g, bins=b)[0] / len(w) * vol
    assert exact.sum() == pytest.approx(vol, rel=1e-9)
    assert np.allclose(exact, sampled, atol=0.01 * vol)
