"""Flushing exposed filaments: moves of the first, last and exposed layers along the normal."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from core.stages import TetMesh, Toolpath
from slicer.toolpath.flush import (
    boundary_surface,
    filament_height,
    flush_toolpath,
    limit_step_angle,
    signed_distance,
)


class RoundFilament:
    """Round filament of area C / v (h_f = w_f), enough for flushing."""

    rate_mm3_s = 6.57

    def filament_size(self, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = np.sqrt(4.0 * self.rate_mm3_s / (np.pi * np.asarray(v, dtype=np.float64)))
        return d, d


def _speed_for_height(h_f: float) -> float:
    return RoundFilament.rate_mm3_s / (0.25 * np.pi * h_f * h_f)


def _box_tets(size: tuple[float, float, float], rotation: np.ndarray | None = None) -> TetMesh:
    """A box [0, size] split into the 6 Kuhn tets of its corners, positively oriented."""
    corners = np.array([[(i >> 0) & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)],
                       dtype=np.float64) * np.asarray(size)
    tets = []
    for a, b, _ in itertools.permutations(range(3)):
        v1 = 1 << a
        v2 = v1 | (1 << b)
        t = [0, v1, v2, 7]
        e = corners[t[1:]] - corners[t[0]]
        if np.linalg.det(e) < 0:
            t[1], t[2] = t[2], t[1]
        tets.append(t)
    if rotation is not None:
        corners = corners @ rotation.T
    return TetMesh(vertices=corners, tets=np.asarray(tets, dtype=np.int32))


def _toolpath(points: np.ndarray, layer: np.ndarray, speed: float, height: float,
              normal: np.ndarray, extrude: np.ndarray | None = None) -> Toolpath:
    n = len(points)
    return Toolpath(position=points, normal=np.broadcast_to(normal, (n, 3)).copy(),
                    layer=layer.astype(np.int32), path=layer.astype(np.int32),
                    height=np.full(n, height), width=np.full(n, 2.0), speed=np.full(n, speed),
                    extrude=np.ones(n, dtype=bool) if extrude is None else extrude,
                    pattern=np.ones(n, dtype=np.int8))


def _slab_job(side: float = 6.0, h: float = 0.5, beta: float = 0.5
              ) -> tuple[TetMesh, Toolpath, float]:
    """Layers at mid-slab heights (k + 1/2) h of a box, h_f = h / beta; one line each."""
    mesh = _box_tets((side, side, side))
    n_layers = round(side / h)
    x = np.linspace(1.0, side - 1.0, 9)
    pts = np.concatenate([np.column_stack([x, np.full_like(x, 3.0), np.full_like(x, (k + 0.5) * h)])
                          for k in range(n_layers)])
    layer = np.repeat(np.arange(n_layers), len(x))
    h_f = h / beta
    return mesh, _toolpath(pts, layer, _speed_for_height(h_f), h, np.array([0.0, 0.0, 1.0])), h_f


def test_boundary_is_closed_and_outward() -> None:
    mesh = _box_tets((2.0, 3.0, 4.0))
    v, f = boundary_surface(mesh)
    assert len(f) == 12
    tri = v[f]
    signed_volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6
    assert signed_volume == pytest.approx(24.0)


def test_filament_height_matches_area() -> None:
    _, tp, h_f = _slab_job()
    assert np.allclose(filament_height(tp, RoundFilament()), h_f)


def test_first_and_last_layers_become_flush_and_inner_layers_stay() -> None:
    mesh, tp, h_f = _slab_job()
    h = float(tp.height[0])
    out, rep = flush_toolpath(tp, mesh, RoundFilament())
    dz = out.position[:, 2] - tp.position[:, 2]
    first, last = tp.layer == 0, tp.layer == tp.layer.max()
    cap = 0.5 * (h_f - h)
    assert np.allclose(dz[first], cap, atol=1e-6)  # bottom now at z = 0
    assert np.allclose(dz[last], -cap, atol=1e-6)  # top now at the top face
    assert np.allclose(dz[~first & ~last], 0.0)
    assert np.allclose(out.position[:, :2], tp.position[:, :2])
    assert rep.moved == first.sum() + last.sum()
    assert rep.moved_up == first.sum() and rep.moved_down == last.sum()
    assert rep.max_mm == pytest.approx(cap)
    assert rep.residual_mm < 1e-6
    # Every filament's top and bottom is now inside or on the surface.
    v, f = boundary_surface(mesh)
    half = 0.5 * h_f * np.array([0.0, 0.0, 1.0])
    d, _ = signed_distance(np.concatenate([out.position + half, out.position - half]), v, f)
    assert d.max() < 1e-6
    # Nothing but the positions changes.
    for name in ("normal", "layer", "path", "height", "width", "speed", "extrude", "pattern"):
        assert np.array_equal(getattr(out, name), getattr(tp, name))


def test_matched_filaments_and_travel_moves_do_not_move() -> None:
    mesh, tp, _ = _slab_job(beta=1.0)  # h_f = H: nothing to flush
    out, rep = flush_toolpath(tp, mesh, RoundFilament())
    assert rep.moved == 0 and np.array_equal(out.position, tp.position)
    mesh, tp, _ = _slab_job()
    travel = tp.layer == 0
    fields = tp.arrays()
    fields["extrude"] = ~travel
    out, rep = flush_toolpath(Toolpath(**fields), mesh, RoundFilament())
    assert np.array_equal(out.position[travel], tp.position[travel])
    assert rep.extruding == int((~travel).sum()) and rep.moved_up == 0


def test_thin_region_keeps_the_filament_centred() -> None:
    # A plate thinner than h_f: both sides stick out; the move is the mean of both (0 here).
    h, h_f = 0.5, 1.0
    mesh = _box_tets((6.0, 6.0, h))
    x = np.linspace(1.0, 5.0, 5)
    pts = np.column_stack([x, np.full_like(x, 3.0), np.full_like(x, 0.5 * h)])
    tp = _toolpath(pts, np.zeros(5, dtype=np.int64), _speed_for_height(h_f), h,
                   np.array([0.0, 0.0, 1.0]))
    out, rep = flush_toolpath(tp, mesh, RoundFilament())
    assert np.allclose(out.position, tp.position) and rep.moved == 0
    assert rep.residual_mm == pytest.approx(0.5 * (h_f - h), abs=1e-6)  # cannot be flush


def test_sloped_top_face_converges_to_flush() -> None:
    # A box tilted by 20 deg about x; the printing direction stays +z, so the top face is
    # oblique to it and one linearised step is not exact: the iterations must converge.
    c, s = np.cos(np.deg2rad(20.0)), np.sin(np.deg2rad(20.0))
    rot = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    mesh = _box_tets((6.0, 6.0, 6.0), rot)
    h, h_f = 0.5, 1.0
    local = np.column_stack([np.linspace(1.5, 4.5, 7), np.full(7, 3.0), np.full(7, 6.0 - 0.3)])
    pts = local @ rot.T  # 0.3 mm under the top face, measured along its normal
    tp = _toolpath(pts, np.zeros(7, dtype=np.int64), _speed_for_height(h_f), h,
                   np.array([0.0, 0.0, 1.0]))
    out, rep = flush_toolpath(tp, mesh, RoundFilament(), iterations=6)
    v, f = boundary_surface(mesh)
    d, _ = signed_distance(out.position + np.array([0.0, 0.0, 0.5 * h_f]), v, f)
    # The top point sticks out 0.5 cos 20 - 0.3 = 0.170 mm along the face normal; moving
    # along -z gains cos 20 per mm: 0.181 mm, below the cap 0.25 mm.
    assert np.abs(d).max() < 2e-3
    assert rep.moved_down == 7 and rep.capped == 0
    assert rep.mean_mm == pytest.approx((0.5 * c - 0.3) / c, abs=2e-3)


def test_step_angle_limit_cuts_a_lone_move_back_to_its_neighbours() -> None:
    x = np.arange(10) * 0.4
    pts = np.column_stack([x, np.zeros(10), np.zeros(10)])
    up = np.tile([0.0, 0.0, 1.0], (10, 1))
    one = np.zeros(10, dtype=np.int64)
    tan14 = np.tan(np.radians(14.0))
    move = np.zeros(10)
    move[4] = -0.33  # one waypoint dives 0.33 mm where its neighbours, 0.4 mm away, stay
    out = limit_step_angle(move, pts, up, one, 14.0)
    assert out[4] == pytest.approx(-0.4 * tan14)
    assert np.allclose(np.delete(out, 4), 0.0)
    # a ramp within the angle is kept as it is
    ramp = np.linspace(0.0, 0.3, 10)  # 0.083 per mm: 4.8 deg
    assert np.allclose(limit_step_angle(ramp, pts, up, one, 14.0), ramp)
    far = np.r_[0.3, 0.3, 0.3, 0.0, 0.0, 0.0, 0.0, -0.3, -0.3, -0.3]
    kept = limit_step_angle(far, pts, up, one, 14.0)
    assert np.all(np.abs(np.diff(kept)) <= 0.4 * tan14 + 1e-12)
    # the drop to 0 is too steep: the run is cut back to a ramp, never moved further
    assert kept[:3] == pytest.approx([3 * 0.4 * tan14, 2 * 0.4 * tan14, 0.4 * tan14])
    assert np.all(np.abs(kept) <= np.abs(far) + 1e-12) and np.all(kept * far >= 0.0)
    # paths are independent: a path's last waypoint does not limit the next path's first
    path = np.r_[np.zeros(5), np.ones(5)].astype(np.int64)
    step = np.r_[np.zeros(5), np.full(5, 0.3)]
    assert np.allclose(limit_step_angle(step, pts, up, path, 14.0), step)
    # a step that already climbs 10 deg out of the plane leaves 4 deg for the moves
    climbing = pts + np.column_stack([np.zeros(10), np.zeros(10), x * np.tan(np.radians(10.0))])
    out = limit_step_angle(move, climbing, up, one, 14.0)
    length, climb = 0.4 / np.cos(np.radians(10.0)), 0.4 * np.tan(np.radians(10.0))
    assert out[4] == pytest.approx(-(length * tan14 - climb))


def test_a_lone_exposed_waypoint_does_not_dive_out_of_its_path() -> None:
    # one line under the top face of a 6 mm box (H 0.5, h_f 1.0, waypoints 0.5 mm apart):
    # its filaments end flush with the top, except at one waypoint that sits 0.25 mm higher
    h, h_f = 0.5, 1.0
    mesh = _box_tets((6.0, 6.0, 6.0))
    x = np.linspace(1.0, 5.0, 9)
    z = np.full_like(x, 5.5)
    z[4] = 5.75
    tp = _toolpath(np.column_stack([x, np.full_like(x, 3.0), z]), np.zeros(9, dtype=np.int64),
                   _speed_for_height(h_f), h, np.array([0.0, 0.0, 1.0]))
    out, rep = flush_toolpath(tp, mesh, RoundFilament())
    dz = out.position[:, 2] - tp.position[:, 2]
    # alone it would move the full 0.25 mm; its steps (0.56 mm, climbing 0.25 mm) already
    # leave the horizontal by 26.6 deg, more than 14: it may not move at all
    allowed = 0.0
    assert dz[4] == pytest.approx(-allowed, abs=1e-6)
    assert np.allclose(np.delete(dz, 4), 0.0)
    assert rep.residual_mm == pytest.approx(0.25 - allowed, abs=1e-6)  # still sticking out
