"""Paper-size parts in the default cell: a tall part is reachable, a steep layer gets a lean;
the shallow tray (planner/cells/tray.toml) takes a steep edge the deep tank refuses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.stages import Toolpath
from planner.cell import CellConfig, load_cell
from planner.nozzle_axis import alpha_of, nozzle_axis
from planner.placement import fit_gel
from planner.plan import plan
from slicer.normals import repair_normals
from tests.planner import synthetic
from tests.planner.synthetic import make_toolpath, random_frames


def test_lean_keeps_alpha_and_deviates_by_the_combined_angle() -> None:
    n, t = random_frames(40, seed=1)
    for tilt, lean in ((0.0, 25.0), (10.0, -30.0), (-15.0, 40.0)):
        ax = nozzle_axis(n, t, np.full(40, np.radians(tilt)), np.full(40, np.radians(lean)))
        assert np.allclose(np.linalg.norm(ax, axis=1), 1.0)
        # motion in the layer: alpha = 90 - tilt whatever the lean
        assert np.allclose(np.degrees(alpha_of(ax, t)), 90.0 - tilt)
        dev = np.degrees(np.arccos(np.clip(-np.einsum("ij,ij->i", ax, n), -1, 1)))
        expect = np.degrees(np.arccos(np.cos(np.radians(tilt)) * np.cos(np.radians(lean))))
        assert np.allclose(dev, expect)


def test_a_200_mm_tall_part_is_reachable(cell: CellConfig) -> None:
    tall = synthetic.rings(20.0, [0.0, 100.0, 200.0], [0.0, 0.0, 0.0], step=2.0)
    result = plan(tall, cell)
    rep = result.report
    assert rep["status"] == "ok" and rep["unreachable"]["count"] == 0
    assert rep["min_clearance_mm"] >= cell.planning.clearance_mm
    # the gel covers the part and the extruder body stays above it
    assert rep["gel_fill_mm"] >= cell.placement.offset_mm[2] + 200.0
    tr = result.trajectory
    assert np.all(np.abs(tr.alpha[tr.extrude & (tr.waypoint >= 0)] - 90.0) < 1.0)


def test_steep_layer_gets_a_lean_not_a_tilt(cell: CellConfig) -> None:
    # a bowl-shaped bottom layer (normals 50 deg towards the axis) under a 200 mm part: at
    # alpha = 90 deg along -normal the extruder body would dip into the 225 mm of gel
    tp = synthetic.rings(30.0, [0.0, 200.0], [50.0, 0.0], step=1.0)
    gel = fit_gel(cell, tp).tank.gel_fill_mm
    body = cell.tool.nozzle_length_mm * np.cos(np.radians(50.0))
    assert cell.placement.offset_mm[2] + body < gel  # the premise: -normal is not enough
    result = plan(tp, cell)
    rep = result.report
    assert rep["unreachable"]["count"] == 0
    assert rep["min_clearance_mm"] >= cell.planning.clearance_mm - 1e-6
    o, tr = result.orientation, result.trajectory
    bottom = (tr.waypoint >= 0) & (tr.waypoint < np.flatnonzero(tp.path == 1)[0]) & tr.extrude
    lean = np.degrees(np.abs(o.lean[bottom]))
    assert lean.mean() > 3.0 and lean.max() <= cell.planning.lean_max_deg + 1e-9
    a = tr.alpha[tr.extrude]
    assert a.min() >= cell.planning.alpha_min_deg - 1e-6
    assert a.max() <= cell.planning.alpha_max_deg + 1e-6
    # the lean keeps the printing angle near 90 deg on the bottom ring
    assert np.median(np.abs(tr.alpha[bottom] - 90.0)) < 2.0
    assert rep["lean_deg"]["max"] > 3.0
    # smooth along the ring: the lean changes by at most 1 deg per sample
    ring = np.flatnonzero(bottom)
    ring = ring[ring + 1 < len(o.lean)]
    assert np.degrees(np.abs(o.lean[ring + 1] - o.lean[ring])).max() <= 1.0 + 1e-9


def test_normal_spikes_are_repaired_and_counted() -> None:
    tp = synthetic.lines(n_lines=1, length=20.0)
    n = np.array(tp.normal)
    n[10] = [0.0, 0.86, 0.5]  # one waypoint 60 deg off its neighbours
    n[20:22] = [0.5, 0.0, 0.86]  # two in a row
    spiky = make_toolpath(np.array(tp.position), n, np.array(tp.path))
    fixed, mask = repair_normals(spiky)
    assert set(np.flatnonzero(mask)) == {10, 20, 21}
    assert np.allclose(fixed.normal, [0.0, 0.0, 1.0])
    # a genuine bend (all neighbours turn together) is left alone
    bend = np.array(tp.normal)
    bend[20:] = [0.5, 0.0, 0.86]
    _, mask = repair_normals(make_toolpath(np.array(tp.position), bend, np.array(tp.path)))
    assert not mask.any()


def test_repeated_waypoints_take_no_time(cell: CellConfig) -> None:
    tp = synthetic.lines(n_lines=1, length=10.0)
    P = np.insert(np.array(tp.position), 5, tp.position[5], axis=0)  # waypoint 5 twice
    rep = make_toolpath(P, np.tile([0.0, 0.0, 1.0], (len(P), 1)), np.zeros(len(P), np.int32))
    result = plan(rep, cell)
    tr = result.trajectory
    assert np.all(np.diff(tr.t) > 0)
    # the whole line at the toolpath speed (10 mm/s), plus the ramps at both ends (the entry
    # before the first waypoint and the exit after the last are not part of it)
    wp = np.flatnonzero(tr.waypoint >= 0)
    assert tr.t[wp[-1]] - tr.t[wp[0]] < 10.0 / 10.0 + 1.0
    assert np.array_equal(tr.waypoint[tr.waypoint >= 0], np.arange(len(P)))


def test_gel_is_filled_to_the_cover_above_the_part(cell: CellConfig) -> None:
    short = synthetic.rings(20.0, [0.0, 28.0], [0.0, 0.0], step=4.0)
    tall = synthetic.rings(20.0, [0.0, 260.0], [0.0, 0.0], step=4.0)
    lift = cell.placement.offset_mm[2]
    assert np.isclose(fit_gel(cell, short).tank.gel_fill_mm, lift + 28.0 + cell.tank.gel_cover_mm)
    assert fit_gel(cell, tall).tank.gel_fill_mm == cell.tank.gel_fill_mm  # never above the fill


def _steep_edge(slope_deg: float) -> Toolpath:
    """Stripes running down a flat part's edge (like the membrane's dome at 0.70 mm layers):
    from y = 35 mm outwards, the layer's normal tilted ``slope_deg`` towards +y, and one flat
    stripe along the far edge at y = -50 mm, so the part is 100 mm across."""
    slope = np.radians(slope_deg)
    t = np.arange(0.0, 15.0 + 1e-9, 0.5)
    pos, nrm, path = [], [], []
    for i, x in enumerate(np.arange(-20.0, 21.0, 4.0)):
        P = np.stack([np.full_like(t, x), 35.0 + t * np.cos(slope), 20.0 - t * np.sin(slope)], 1)
        pos.append(P if i % 2 == 0 else P[::-1])
        nrm.append(np.tile([0.0, np.sin(slope), np.cos(slope)], (len(t), 1)))
        path.append(np.full(len(t), i))
    xs = np.arange(-20.0, 20.0 + 1e-9, 0.5)
    pos.append(np.stack([xs, np.full_like(xs, -50.0), np.full_like(xs, 20.0)], 1))
    nrm.append(np.tile([0.0, 0.0, 1.0], (len(xs), 1)))
    path.append(np.full(len(xs), len(path)))
    return make_toolpath(np.concatenate(pos), np.concatenate(nrm), np.concatenate(path))


@pytest.mark.slow  # the deep tank's refusal re-plans at every other placement
def test_the_tray_cell_takes_a_steep_edge_the_deep_tank_refuses(cell: CellConfig) -> None:
    tray = load_cell(Path(__file__).resolve().parents[2] / "planner" / "cells" / "tray.toml")
    # only the tank differs: the same arm, tool and limits
    assert tray.robot == cell.robot and tray.tool == cell.tool
    assert tray.planning == cell.planning
    assert tray.tank.inner_size_mm[2] < 0.4 * cell.tank.inner_size_mm[2]
    tp = _steep_edge(60.0)
    # down a 60 deg edge the nozzle leans ~56 deg out (alpha >= 70 against the step):
    # 300 mm up the nozzle, the extruder is ~250 mm out, where the deep tank's wall stands
    deep = plan(tp, cell).report
    assert deep["status"] != "ok"
    shallow = plan(tp, tray).report
    assert shallow["status"] == "ok" and shallow["unreachable"]["count"] == 0
    assert shallow["min_clearance_mm"] >= tray.planning.clearance_mm - 1e-6


def test_the_fix_names_a_bundled_cell_only_where_the_job_planned() -> None:
    # the deep tank refuses the steep edge (above), the tray plans it: `mesp plan` tries the
    # other bundled cells and names the tray because it planned there, and says so
    from planner.other_cells import checked_fix, try_cells

    trials = try_cells(_steep_edge(60.0), None)
    assert [t.name for t in trials] == ["tray"] and trials[0].ok
    fix = checked_fix(trials, "use a wider tank")
    assert fix.startswith("plan with --cell ") and fix.endswith(
        "tray.toml (checked: the job plans ok in the tray cell)")
    refused = trials[0]._replace(ok=False, reason="refused (wall)")
    assert checked_fix([refused], "use a wider tank") == (
        "use a wider tank (not checked; no bundled cell plans it either: tried tray: refused "
        "(wall))")
