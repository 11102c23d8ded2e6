"""Steps that leave their layer (slicer.toolpath.relief)."""

from __future__ import annotations

import numpy as np
import pytest

from core.stages import Toolpath
from slicer.toolpath.relief import relieve_bends, step_elevation


def _path(z: np.ndarray, step: float = 0.5, height: float = 0.7) -> Toolpath:
    """One extruding path along x with heights ``z`` (mm), printing direction +z."""
    n = len(z)
    x = np.arange(n) * step
    return Toolpath(position=np.column_stack([x, np.zeros(n), z]),
                    normal=np.tile([0.0, 0.0, 1.0], (n, 1)), layer=np.zeros(n, np.int32),
                    path=np.zeros(n, np.int32), height=np.full(n, height),
                    width=np.full(n, 2.0), speed=np.full(n, 10.0), extrude=np.ones(n, bool),
                    pattern=np.ones(n, np.int8))


def test_a_flat_or_gently_sloped_path_is_left_alone() -> None:
    for z in (np.zeros(20), 0.1 * np.arange(20)):  # 11 deg: within the 20 deg limit
        tp = _path(z)
        out, relief = relieve_bends(tp)
        assert out is tp and len(relief.moved) == 0 and relief.left == 0


def test_a_waypoint_kinked_out_of_the_layer_is_moved_onto_the_chord() -> None:
    z = np.zeros(20)
    z[10] = 0.3  # steps rising and falling 31 deg
    tp = _path(z)
    i, e_in, e_out, _, _ = step_elevation(tp)
    assert np.degrees(np.abs(e_in[i == 10])) == pytest.approx(np.degrees(np.arctan(0.6)))
    assert np.degrees(e_out[i == 10]) == pytest.approx(-np.degrees(np.arctan(0.6)))
    out, relief = relieve_bends(tp)
    assert list(relief.moved) == [10]
    assert relief.offset_mm == pytest.approx([-0.3])
    assert out.position[10] == pytest.approx([5.0, 0.0, 0.0])
    # only the position changes: widths, speeds, normals, order stay
    for name in ("normal", "width", "speed", "height", "path", "extrude"):
        assert np.array_equal(getattr(out, name), getattr(tp, name)), name
    assert relief.left == 0 and relief.ink_change < 0.0  # two steps shorter


def test_a_step_up_is_spread_but_no_waypoint_moves_more_than_its_cap() -> None:
    # a path that climbs 0.7 mm (one layer height) within one 0.5 mm step: the bend at both
    # ends is relieved, each waypoint by at most H / 2, and what the cap leaves is reported
    z = np.where(np.arange(20) >= 10, 0.7, 0.0)
    tp = _path(z)
    out, relief = relieve_bends(tp, cap=0.5)
    assert len(relief.moved) >= 2
    assert np.abs(out.position[:, 2] - z).max() <= 0.5 * 0.7 + 1e-9
    steepest = np.degrees(np.abs(np.arctan(np.diff(out.position[:, 2]) / 0.5))).max()
    assert steepest < np.degrees(np.arctan(0.7 / 0.5))  # 54 deg before
    _, e_in, e_out, _, _ = step_elevation(out)
    beyond = (np.abs(e_in) > np.radians(20)) | (np.abs(e_out) > np.radians(20))
    assert relief.left == int(beyond.sum())
    # without a cap to spend nothing moves
    same, none = relieve_bends(tp, cap=0.0)
    assert same is tp and len(none.moved) == 0 and none.left > 0


def test_path_ends_travel_and_other_paths_are_not_bends() -> None:
    z = np.zeros(20)
    z[[0, 19]] = 1.0  # the ends of the path: no step on one side
    tp = _path(z)
    path = tp.path.copy()
    path[10:] = 1  # a new path starts at 10: 9 -> 10 is no step of either
    z2 = z.copy()
    z2[10] = 0.6
    split = Toolpath(position=np.column_stack([tp.position[:, :2], z2]), normal=tp.normal,
                     layer=tp.layer, path=path, height=tp.height, width=tp.width,
                     speed=tp.speed, extrude=tp.extrude, pattern=tp.pattern)
    _, relief = relieve_bends(split)
    assert 0 not in relief.moved and 19 not in relief.moved and 10 not in relief.moved
