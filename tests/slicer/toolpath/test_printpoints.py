"""compas_slicer printpoints and CSV exports of a toolpath."""

from __future__ import annotations

import json

import numpy as np

from slicer.toolpath.printpoints import (
    CSV_COLUMNS,
    PRINTPOINT_FIELDS,
    printpoints_json,
    tangents,
    waypoints_csv,
)
from tests.planner import synthetic


def test_printpoints_carry_compas_slicer_fields_in_print_order() -> None:
    tp = synthetic.dome(radius=10.0, cap=3.0, rings=2, step=1.0)
    data = json.loads(printpoints_json(tp))
    assert list(data) == [str(i) for i in range(len(tp))]
    for i in (0, len(tp) // 2, len(tp) - 1):
        pp = data[str(i)]
        assert set(pp) == set(PRINTPOINT_FIELDS)
        assert np.allclose(pp["point"], tp.position[i])
        assert np.allclose(pp["up_vector"], tp.normal[i])
        assert pp["velocity"] == tp.speed[i] and pp["layer_height"] == tp.height[i]
        assert pp["extruder_toggle"] is bool(tp.extrude[i])
        assert set(pp["frame"]) == {"point", "xaxis", "yaxis"}
        x, y = np.array(pp["frame"]["xaxis"]), np.array(pp["frame"]["yaxis"])
        up = np.array(pp["up_vector"])
        # compas_slicer's frame: x = up x mesh_normal, y = mesh_normal, all orthonormal
        assert np.allclose(np.cross(up, y), x, atol=1e-9)
        assert np.allclose([x @ x, y @ y, x @ y, x @ up], [1, 1, 0, 0], atol=1e-9)
        assert pp["attributes"]["width_mm"] == tp.width[i]


def test_tangent_follows_the_path_and_is_in_the_layer() -> None:
    tp = synthetic.lines(n_lines=2, length=5.0, step=1.0)
    t = tangents(tp)
    first = tp.path == 0
    assert np.allclose(t[first], [1.0, 0.0, 0.0])  # path 0 runs along +x, its end included
    assert np.allclose(t[~first], [-1.0, 0.0, 0.0])
    assert np.allclose(np.sum(t * tp.normal, axis=1), 0.0)


def test_csv_has_one_row_per_waypoint() -> None:
    tp = synthetic.lines(n_lines=2, length=5.0, step=1.0)
    text = waypoints_csv(tp)
    lines = text.strip().splitlines()
    assert lines[0].split(",") == list(CSV_COLUMNS)
    rows = np.loadtxt(lines[1:], delimiter=",")
    assert rows.shape == (len(tp), len(CSV_COLUMNS))
    assert np.allclose(rows[:, 3:6], tp.position, atol=1e-6)
    assert np.array_equal(rows[:, 2], tp.path)
