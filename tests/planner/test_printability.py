"""The planner's bend test at slicing time (planner/printability.py)."""

from __future__ import annotations

import numpy as np

from core.stages import Toolpath
from planner.cell import CellConfig
from planner.printability import check, directions
from planner.refusal import bends
from tests.planner import synthetic
from tests.planner.synthetic import make_toolpath


def _step_up() -> Toolpath:
    """A flat path that steps 1.5 mm straight up along its own normal and goes on: no nozzle
    axis keeps alpha in [70, 110] deg of both the flat and the vertical steps."""
    x = np.arange(0.0, 10.01, 0.5)
    flat = np.column_stack([x, np.zeros_like(x), np.full_like(x, 5.0)])
    up = np.array([[10.0, 0.0, 5.75], [10.0, 0.0, 6.5]])
    on = np.column_stack([10.5 + x, np.zeros_like(x), np.full_like(x, 6.5)])
    pos = np.concatenate([flat, up, on])
    return make_toolpath(pos, np.tile([0.0, 0.0, 1.0], (len(pos), 1)),
                         np.zeros(len(pos), np.int32))


def test_a_bend_is_named_at_slicing_time_as_the_planner_will_refuse_it(
        cell: CellConfig) -> None:
    tp = _step_up()
    section, note = check(tp, cell)
    assert section["refused_waypoints"] == 3 and section["first_waypoint"] == 20
    assert section["first_layer"] == 0 and section["cause"] == "bend"
    assert note is not None and note == section["note"]
    assert "waypoint 20 (layer 0" in note and "`mesp plan` will refuse" in note
    assert "fix: re-slice" in note and "checked: it serves all 3" in note
    # the same waypoints the placement search refuses, on the same directions
    assert list(bends(directions(tp, cell).toolpath, cell).waypoint) == [20, 21, 22]


def test_a_printable_toolpath_gets_no_note(cell: CellConfig) -> None:
    section, note = check(synthetic.dome(radius=30.0, cap=6.0, rings=3, step=1.0), cell)
    assert note is None and section["refused_waypoints"] == 0
    assert section["alpha_range_deg"] == [70.0, 110.0]


def test_the_directions_are_the_planners_repaired_and_smoothed_ones(cell: CellConfig) -> None:
    tp = synthetic.dome(radius=30.0, cap=6.0, rings=3, step=1.0)
    normal = np.array(tp.normal)
    normal[5] = [0.6, 0.0, 0.8]  # a one-waypoint spike
    spiked = make_toolpath(np.array(tp.position), normal, np.array(tp.path))
    out = directions(spiked, cell)
    assert out.repaired[5] and out.repaired.sum() == 1
    assert np.allclose(np.linalg.norm(out.toolpath.normal, axis=1), 1.0)
    assert np.degrees(out.smoothed.max()) <= cell.planning.smooth_max_deg + 1e-6
