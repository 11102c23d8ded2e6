"""UR5e kinematics against roboticstoolbox, finite differences and IK round trips."""

from __future__ import annotations

import numpy as np
import pytest

from planner import kinematics as kin


@pytest.fixture(scope="module")
def qs() -> np.ndarray:
    return np.random.default_rng(7).uniform(-np.pi, np.pi, (40, 6))


def test_dh_parameters_are_e_series() -> None:
    assert np.allclose(kin.D, [0.1625, 0, 0, 0.1333, 0.0997, 0.0996])
    assert np.allclose(kin.A, [0, -0.425, -0.3922, 0, 0, 0])


def test_fk_and_jacobian_match_rtb(qs: np.ndarray) -> None:
    robot = kin.rtb_robot()
    T = kin.fk(qs)
    J = kin.jacobian(qs)
    for i, q in enumerate(qs[:15]):
        assert np.allclose(robot.fkine(q).A, T[i], atol=1e-12)
        assert np.allclose(robot.jacob0(q), J[i], atol=1e-12)


def test_jacobian_matches_finite_differences(qs: np.ndarray) -> None:
    tool = np.eye(4)
    tool[:3, 3] = [0.01, -0.02, 0.29]
    J = kin.jacobian(qs, tool)
    h = 1e-6
    for j in range(6):
        dq = np.zeros(6)
        dq[j] = h
        Tp, Tm = kin.fk(qs + dq, tool), kin.fk(qs - dq, tool)
        v = (Tp[:, :3, 3] - Tm[:, :3, 3]) / (2 * h)
        dR = (Tp[:, :3, :3] - Tm[:, :3, :3]) / (2 * h)
        W = dR @ np.swapaxes(kin.fk(qs, tool)[:, :3, :3], 1, 2)  # skew(omega)
        w = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
        assert np.allclose(J[:, :3, j], v, atol=1e-7)
        assert np.allclose(J[:, 3:, j], w, atol=1e-7)


def test_batched_shapes() -> None:
    q = np.zeros((2, 3, 6))
    assert kin.fk(q).shape == (2, 3, 4, 4)
    assert kin.jacobian(q).shape == (2, 3, 6, 6)
    assert kin.frames(q).shape == (2, 3, 7, 4, 4)


def test_ik_round_trip_all_eight_branches(qs: np.ndarray) -> None:
    T = kin.fk(qs)
    sol, ok = kin.ik(T)
    assert sol.shape == (len(qs), 8, 6)
    # every branch that exists reproduces the pose
    err = np.abs(kin.fk(np.where(ok[..., None], sol, 0.0)) - T[:, None])
    assert np.all(err[ok] < 1e-9)
    # the configuration we started from is one of the branches
    d = np.abs(np.angle(np.exp(1j * (sol - qs[:, None, :])))).max(axis=2)
    assert np.all(np.nanmin(np.where(ok, d, np.inf), axis=1) < 1e-8)
    # and configurations are recovered on each of the 8 branches (each branch index used)
    assert set(kin.branch_of(qs)) == set(range(8))
    # eight distinct solutions for a generic pose well inside the workspace
    q0 = np.radians([20.0, -70.0, 80.0, -100.0, -80.0, 30.0])
    s0, ok0 = kin.ik(kin.fk(q0))
    assert ok0.all()
    assert len(np.unique(np.round(s0, 6), axis=0)) == 8


def test_ik_reports_out_of_reach() -> None:
    T = np.eye(4)
    T[:3, 3] = [2.0, 0.0, 0.5]
    _, ok = kin.ik(T)
    assert not ok.any()


def test_singularity_margin_vanishes_with_det() -> None:
    q = np.random.default_rng(3).uniform(-np.pi, np.pi, (100, 6))
    det = np.abs(np.linalg.det(kin.jacobian(q)))
    m = kin.singularity_margin(q)
    q_wrist = q.copy()
    q_wrist[:, 4] = 0.0
    assert np.allclose(kin.singularity_margin(q_wrist), 0.0)
    assert np.allclose(np.abs(np.linalg.det(kin.jacobian(q_wrist))), 0.0, atol=1e-12)
    assert np.all(m > 0) and np.all(det > 0)
