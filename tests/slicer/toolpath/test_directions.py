"""Printing directions: downward waypoints and jumps between neighbours are counted."""

from __future__ import annotations

import numpy as np
import pytest

from core.stages import Toolpath
from slicer.toolpath.directions import direction_report


def toolpath(normals: np.ndarray, path: np.ndarray | None = None,
             extrude: np.ndarray | None = None) -> Toolpath:
    n = len(normals)
    normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    return Toolpath(position=np.column_stack([np.arange(n, dtype=float), np.zeros((n, 2))]),
                    normal=normals, layer=np.arange(n, dtype=np.int32) // 2,
                    path=np.zeros(n, dtype=np.int32) if path is None else path.astype(np.int32),
                    height=np.full(n, 0.6), width=np.full(n, 1.0), speed=np.full(n, 10.0),
                    extrude=np.ones(n, dtype=bool) if extrude is None else extrude,
                    pattern=np.zeros(n, dtype=np.int8))


def test_upright_directions_have_nothing_to_report() -> None:
    r = direction_report(toolpath(np.tile([0.0, 0.0, 1.0], (5, 1))))
    assert r["downward"] == 0 and r["jumps"] == 0
    assert r["max_from_up_deg"] == pytest.approx(0.0, abs=1e-6)


def test_a_downward_waypoint_is_counted_with_its_layer() -> None:
    n = np.tile([0.0, 0.0, 1.0], (6, 1))
    n[4] = [np.sin(np.radians(120)), 0.0, np.cos(np.radians(120))]
    r = direction_report(toolpath(n))
    assert r["downward"] == 1
    assert r["downward_layers"] == [2]
    assert r["max_from_up_deg"] == pytest.approx(120.0)


def test_a_jump_is_counted_within_a_path_only() -> None:
    tilt = [np.sin(np.radians(40)), 0.0, np.cos(np.radians(40))]
    n = np.array([[0, 0, 1], [0, 0, 1], tilt, tilt], dtype=float)
    within = direction_report(toolpath(n))
    assert within["jumps"] == 1 and within["max_jump_deg"] == pytest.approx(40.0)
    across = direction_report(toolpath(n, path=np.array([0, 0, 1, 1])))
    assert across["jumps"] == 0


def test_travel_waypoints_are_not_counted() -> None:
    n = np.array([[0, 0, 1], [0, 0, -1], [0, 0, 1]], dtype=float)
    r = direction_report(toolpath(n, extrude=np.array([True, False, True])))
    assert r["downward"] == 0 and r["jumps"] == 0
