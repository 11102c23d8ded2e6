"""Nozzle orientation: alpha = 90 by default, a tilt within [70, 110] deg near a wall."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from core.stages import Toolpath
from planner.cell import CellConfig
from planner.nozzle_axis import nozzle_axis, tool_rotation
from planner.placement import model_transform
from planner.plan import plan
from planner.reach import COLLISION, OK, Reach
from planner.samples import resample
from tests.planner.synthetic import make_toolpath


def _wall_case(cell: CellConfig) -> tuple[CellConfig, Toolpath]:
    """A line on a layer sloping 25 deg down towards the +x tank wall, moving to the wall.

    The normal leans 25 deg towards the wall, so at alpha = 90 deg the nozzle shaft and the
    extruder lean over the wall; tilting back (alpha < 90) clears it.
    """
    lean = np.radians(25.0)
    x = np.arange(0.0, 20.0 + 1e-9, 0.5)
    pos = np.stack([x, np.zeros_like(x), 15.0 - x * np.tan(lean)], axis=1)
    normal = np.tile([np.sin(lean), 0.0, np.cos(lean)], (len(x), 1))
    tp = make_toolpath(pos, normal, np.zeros(len(x), np.int32))
    # bbox bottom centre 80 mm from the tank centre: the line ends 60 mm from the wall
    placement = dataclasses.replace(cell.placement, offset_mm=(80.0, 0.0, 10.0), yaw_deg=0.0,
                                    search=False)
    # the robot on the table top (no pedestal): from higher up some spin clears the wall
    robot = dataclasses.replace(cell.robot, base_xyz_mm=(0.0, 0.0, 0.0))
    return dataclasses.replace(cell, placement=placement, robot=robot), tp


def test_wall_forces_a_tilt_within_the_allowed_range(cell: CellConfig) -> None:
    wall_cell, tp = _wall_case(cell)
    reach = Reach(wall_cell)
    # at alpha = 90 deg no spin clears the wall at the end of the line
    model_T = model_transform(wall_cell, (tp.position.min(0), tp.position.max(0)),
                              np.array(wall_cell.placement.offset_mm), 0.0)
    s = resample(tp, model_T, wall_cell)
    end = np.array([len(s.tcp) - 1])
    ax = nozzle_axis(s.normal[end], s.tangent[end], np.array([0.0]))
    grid = np.linspace(-np.pi, np.pi, 24, endpoint=False)
    q = reach.solve(np.repeat(s.tcp[end], 24, axis=0),
                    tool_rotation(np.repeat(ax, 24, axis=0), grid), reach.home)
    ev = reach.check(q)
    assert not np.any(ev.status == OK)
    assert np.any(ev.status == COLLISION)

    result = plan(tp, wall_cell)
    rep = result.report
    assert rep["unreachable"]["count"] == 0
    a = result.trajectory.alpha[result.trajectory.extrude]
    assert a.min() >= 70.0 - 1e-6 and a.max() <= 110.0 + 1e-6
    assert np.abs(a - 90.0).max() > 4.0  # it did tilt
    assert a.min() < 90.0  # back, away from the wall
    assert rep["alpha_deg"]["tilted_samples"] > 0
    assert rep["min_clearance_mm"] >= wall_cell.planning.clearance_mm - 1e-6


@pytest.mark.parametrize("name", ["lines_tp", "spiral_tp"])
def test_flat_layers_print_at_alpha_90(name: str, request: pytest.FixtureRequest,
                                        cell: CellConfig) -> None:
    result = plan(request.getfixturevalue(name), cell)
    tr = result.trajectory
    inner = tr.extrude & (tr.waypoint >= 0)
    assert np.all(np.abs(tr.alpha[inner] - 90.0) < 1.0)  # the spiral climbs 0.9 deg
    assert result.report["unreachable"]["count"] == 0


def test_unreachable_waypoints_are_reported_with_reasons(cell: CellConfig) -> None:
    wall_cell, tp = _wall_case(cell)
    normal = np.array(tp.normal)
    # growth pointing down: the nozzle would have to point up out of the gel, beyond any
    # tilt (20 deg) and lean (40 deg); six waypoints, too many for the spike repair
    lean = np.radians(160.0)
    normal[30:36] = [np.sin(lean), 0.0, np.cos(lean)]
    bad = make_toolpath(np.array(tp.position), normal, np.zeros(len(tp), np.int32))
    # placement is fixed and checks only a subsample; the plan itself must report them
    result = plan(bad, wall_cell, placement=_fixed_placement(wall_cell, bad))
    un = result.report["unreachable"]
    assert un["count"] >= 6
    covered = set()
    for run in un["waypoints"]:
        covered |= set(range(run["first"], run["last"] + 1))
        assert run["reason"]
    assert set(range(30, 36)) <= covered
    assert result.status == "unreachable waypoints"


def _fixed_placement(cell: CellConfig, tp: Toolpath):  # type: ignore[no-untyped-def]
    from planner.placement import Placement

    box = (tp.position.min(0), tp.position.max(0))
    T = model_transform(cell, box, np.array(cell.placement.offset_mm), cell.placement.yaw_deg)
    return Placement(T, cell.placement.offset_mm, cell.placement.yaw_deg, 0, 0.0, 1, 0, -1)


def test_ramp_keeps_peaks_and_limits_the_slope() -> None:
    from planner.orientation import ramp

    dev = np.zeros(60)
    dev[20:25] = 0.2
    dev[45] = -0.1
    out = ramp(dev, 0.05)
    assert np.allclose(out[20:25], 0.2) and np.isclose(out[45], -0.1)
    assert np.abs(np.diff(out)).max() <= 0.05 + 1e-12
    assert np.all(np.abs(out) >= np.abs(dev) - 1e-12)


def test_tilt_levels_start_at_zero_and_respect_alpha(cell: CellConfig) -> None:
    from planner.orientation import tilt_levels

    levels = np.degrees(tilt_levels(cell, np.radians(np.array([90.0]))))
    assert levels[0] == 0.0
    assert np.all(np.abs(np.diff(np.abs(levels))) >= -1e-9)  # by size
    assert levels.min() >= -20.0 - 1e-9 and levels.max() <= 20.0 + 1e-9
    # a steeply climbing move (alpha0 = 115) needs at least a 5 deg tilt
    climb = np.degrees(tilt_levels(cell, np.radians(np.array([115.0]))))
    assert climb.min() >= 0.0 - 1e-9 and 25.0 in np.round(climb, 9) and 45.0 in np.round(climb, 9)


def _along_wall_case(cell: CellConfig) -> tuple[CellConfig, Toolpath, np.ndarray]:
    """A line along the +x tank wall, 60 mm from it, normals +z except a middle stretch
    leaning 25 deg towards the wall (the nozzle must lean back there). Returns the cell,
    the toolpath and the model transform (mm)."""
    wall_cell, line = _wall_case(cell)
    lean = np.radians(25.0)
    y = np.arange(-10.0, 10.0 + 1e-9, 0.5)
    pos = np.stack([np.full_like(y, 20.0), y, np.full_like(y, 15.0 - 20.0 * np.tan(lean))], 1)
    normal = np.tile([0.0, 0.0, 1.0], (len(y), 1))
    normal[15:26] = [np.sin(lean), 0.0, np.cos(lean)]
    tp = make_toolpath(pos, normal, np.zeros(len(y), np.int32))
    model_T = model_transform(wall_cell, (line.position.min(0), line.position.max(0)),
                              np.array(wall_cell.placement.offset_mm), 0.0)
    return wall_cell, tp, model_T


def test_batched_repair_picks_the_same_candidates_as_one_at_a_time(
    cell: CellConfig, monkeypatch: pytest.MonkeyPatch
) -> None:
    import planner.orientation as orientation

    wall_cell, tp, model_T = _along_wall_case(cell)
    reach = Reach(wall_cell)
    s = resample(tp, model_T, wall_cell)
    args = (reach, s.tcp, s.normal, s.tangent, s.extrude)
    # the coarse spin search (first and last sample only) misses the leaning stretch: the
    # repair must find the leans
    batched = orientation.choose(*args, coarse=2)
    monkeypatch.setattr(orientation, "REPAIR_BATCH", 1)  # one candidate per check
    single = orientation.choose(*args, coarse=2)
    assert np.any(np.abs(batched.lean) > 1e-6)  # the wall forced repairs
    assert np.all(batched.status == OK)
    for name in ("q", "psi", "tilt", "lean", "status"):
        assert np.array_equal(getattr(batched, name), getattr(single, name)), name


def test_a_sample_whose_axis_spikes_is_checked_for_clearance(cell: CellConfig) -> None:
    """Clearance is computed on every few samples and densely near the requirement; a single
    waypoint whose normal leans 20 deg further towards the wall than its neighbours' (a layer
    curling at its edge) must be checked too, or the nozzle may reach the wall unseen."""
    wall_cell, tp = _wall_case(cell)
    normal = np.array(tp.normal)
    spike = np.radians(45.0)
    spikes = [13, 22, 31]  # apart, so some fall between the strided samples
    normal[spikes] = [np.sin(spike), 0.0, np.cos(spike)]
    spiky = make_toolpath(np.array(tp.position), normal, np.zeros(len(tp), np.int32))
    # the planner's smoothing turns such a spike back by up to smooth_max_deg (20): off,
    # so the spike reaches the orientation stage this test is about
    wall_cell = dataclasses.replace(wall_cell, planning=dataclasses.replace(
        wall_cell.planning, smooth_length_mm=0.0))
    result = plan(spiky, wall_cell, placement=_fixed_placement(wall_cell, spiky))
    wp = result.samples.waypoint
    at_spikes = np.flatnonzero(np.isin(wp, spikes))
    assert len(at_spikes) == len(spikes)
    assert np.all(np.isfinite(result.orientation.clearance[at_spikes]))
    # the neighbours of a spike, where the axis swings in and out, are checked as well
    ax = result.orientation.axis
    turned = np.einsum("ij,ij->i", ax[1:], ax[:-1]) < np.cos(np.radians(2.0))
    assert np.all(np.isfinite(result.orientation.clearance[1:][turned]))
