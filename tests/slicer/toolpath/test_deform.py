"""Width-driven deformation (eqs. 13, 14)."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import InputError
from slicer.toolpath import deform
from slicer.toolpath.surface import face_normals
from tests.slicer.toolpath.pattern_meshes import disc, dome


def test_constant_width_gives_a_rigid_deformation() -> None:
    v, f = disc(10.0, 1.0, jitter=0.2)
    v = dome(v, 4.0, 10.0)
    res = deform.deform_to_constant_width(v, f, np.full(len(v), 1.7), iterations=5)
    assert np.allclose(res.scale, 1.0)
    # rigid: all pairwise distances are kept
    assert np.allclose(res.vertices - res.vertices.mean(0), v - v.mean(0), atol=1e-8)
    assert res.status == "converged"


def test_rotated_layer_stays_rigid_under_constant_width() -> None:
    v, f = disc(6.0, 1.0)
    v = dome(v, 2.0, 6.0)
    c, s = np.cos(0.7), np.sin(0.7)
    rot = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    vr = v @ rot.T
    res = deform.deform_to_constant_width(vr, f, np.full(len(v), 2.0), iterations=3)
    d0 = np.linalg.norm(vr[f[:, 0]] - vr[f[:, 1]], axis=1)
    d1 = np.linalg.norm(res.vertices[f[:, 0]] - res.vertices[f[:, 1]], axis=1)
    assert np.allclose(d0, d1, atol=1e-8)


def test_variable_width_evens_out_the_effective_width() -> None:
    v, f = disc(12.0, 0.8)
    v = dome(v, 3.0, 12.0)
    w = 1.2 + 0.05 * np.linalg.norm(v[:, :2], axis=1)
    res = deform.deform_to_constant_width(v, f, w, iterations=15)
    wf = w[f].mean(axis=1)
    before = wf.std() / wf.mean()
    eff = wf * res.achieved
    after = eff.std() / eff.mean()
    assert after < 0.5 * before
    assert np.all(np.diff(res.trace) <= 1e-9 * res.trace[0])  # local-global never increases
    # faces with a larger width shrink, smaller ones grow
    assert np.corrcoef(wf, res.achieved)[0, 1] < -0.9
    _, area = face_normals(res.vertices, f)
    assert area.min() > 0.0
    assert res.scale == pytest.approx(
        float((wf * face_normals(v, f)[1]).sum() / face_normals(v, f)[1].sum()) / wf)


def test_scale_deviation_of_a_uniformly_scaled_layer() -> None:
    v, f = disc(5.0, 1.0)
    f = f.astype(np.int64)
    _, area = face_normals(v, f)
    ones = np.ones(len(f))
    assert deform.scale_deviation(2.0 * v, f, area, 2.0 * ones)[0] == pytest.approx(0.0, abs=1e-9)
    dev, achieved = deform.scale_deviation(2.0 * v, f, area, ones)
    assert dev == pytest.approx(1.0) and np.allclose(achieved, 2.0)


def test_tolerance_stops_the_iterations_once_the_scale_is_reached() -> None:
    v, f = disc(12.0, 0.8)
    v = dome(v, 3.0, 12.0)
    w = 1.2 + 0.05 * np.linalg.norm(v[:, :2], axis=1)
    full = deform.deform_to_constant_width(v, f, w, iterations=300)
    res = deform.deform_to_constant_width(v, f, w, iterations=300, scale_tol=0.02)
    assert res.status == "within_tolerance"
    assert res.deviation <= 0.02 < deform.deform_to_constant_width(v, f, w, 1).deviation
    assert 0 < len(res.trace) < len(full.trace)
    assert full.deviation <= res.deviation
    # what the deviation reports is the achieved scale against eq. 14's
    dev = np.abs(res.achieved / res.scale - 1.0)
    _, area = face_normals(v, f)
    assert np.sum(area[dev <= res.deviation + 1e-12]) >= 0.9 * area.sum()


def test_a_layer_already_within_tolerance_is_not_moved() -> None:
    v, f = disc(6.0, 1.0)
    w = np.full(len(v), 2.0) + 0.001 * v[:, 0]  # 0.3 % spread: within 1 %
    res = deform.deform_to_constant_width(v, f, w, iterations=50, scale_tol=0.01)
    assert res.status == "within_tolerance" and len(res.trace) == 0
    assert np.array_equal(res.vertices, v)


def test_deform_rejects_bad_width() -> None:
    v, f = disc(5.0, 1.0)
    with pytest.raises(InputError):
        deform.deform_to_constant_width(v, f, np.zeros(len(v)), 3)
    with pytest.raises(InputError):
        deform.deform_to_constant_width(v, f, np.ones(3), 3)
    with pytest.raises(InputError):
        deform.deform_to_constant_width(v, f, np.ones(len(v)), 3, scale_tol=-0.1)


def test_planar_local_step_matches_the_svd_rotation() -> None:
    rng = np.random.default_rng(3)
    src = rng.normal(size=(50, 3, 3))
    src -= src.mean(axis=1, keepdims=True)
    # a rotated, slightly distorted copy
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    dst = src @ q.T + 0.05 * rng.normal(size=src.shape)
    dst -= dst.mean(axis=1, keepdims=True)
    scale = rng.uniform(0.5, 2.0, 50)
    # reference: 3D Kabsch on the stack, then project onto the current plane as the solver's
    # targets lie in it
    s1, s2 = deform._frames(src)
    src2 = np.stack([np.einsum("fki,fi->fk", src, s1), np.einsum("fki,fi->fk", src, s2)], 2)
    got = deform._planar_targets(src2, dst, scale)
    e1, e2 = deform._frames(dst)
    n = np.cross(e1, e2)
    ref = scale[:, None, None] * np.einsum("fij,fkj->fki", deform._rotations(src, dst), src)
    ref_in = ref - np.einsum("fki,fi->fk", ref, n)[:, :, None] * n[:, None, :]
    # the 3D optimum maps the source plane onto the current plane up to the normal tilt
    cos_sim = np.einsum("fki,fki->f", got, ref_in) / (
        np.linalg.norm(got, axis=(1, 2)) * np.linalg.norm(ref_in, axis=(1, 2)))
    assert np.all(cos_sim > 0.99)
    assert np.allclose(np.linalg.norm(got, axis=2), scale[:, None] * np.linalg.norm(src, axis=2))


def test_two_components_deform_independently() -> None:
    v1, f1 = disc(6.0, 1.0)
    v2, f2 = disc(5.0, 1.0)
    v = np.concatenate([v1, v2 + np.array([20.0, 0.0, 0.0])])
    f = np.concatenate([f1, f2 + len(v1)])
    w = np.concatenate([np.full(len(v1), 1.0), np.full(len(v2), 2.0)])
    res = deform.deform_to_constant_width(v, f, w, iterations=20)
    assert np.all(np.isfinite(res.vertices))
    # each piece is uniformly scaled: by s = W_mean / W, so the wide one shrinks
    assert np.allclose(res.achieved[: len(f1)], res.scale[: len(f1)], rtol=1e-3)
    assert np.allclose(res.achieved[len(f1):], res.scale[len(f1):], rtol=1e-3)
    assert np.allclose(res.vertices[len(v1):].mean(axis=0), v[len(v1):].mean(axis=0))
