"""Model placement: search, fit checks, and refusal of an unreachable placement."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from core.errors import InputError
from core.stages import Toolpath
from planner.cell import CellConfig
from planner.placement import YAW_APART_DEG, choose_placement, fit_gel
from planner.plan import plan
from planner.reach import Reach
from planner.status import PlanStatus
from tests.planner import synthetic


def test_search_keeps_model_inside_tank(cell: CellConfig, dome_tp: Toolpath) -> None:
    p = choose_placement(Reach(cell), dome_tp)
    assert p.unreachable == 0
    pts = dome_tp.position @ p.model_T[:3, :3].T + p.model_T[:3, 3]
    local = pts - cell.tank_in_base[:3, 3]
    half = np.array(cell.tank.inner_size_mm[:2]) / 2 - cell.placement.wall_margin_mm
    assert np.all(np.abs(local[:, :2]) <= half + 1e-6)
    assert np.isclose(local[:, 2].min(), cell.placement.offset_mm[2])


def test_unreachable_placement_is_refused_with_a_clear_message(cell: CellConfig) -> None:
    # a hemisphere cap: normals up to 90 deg, beyond tilt (20 deg) and lean (40 deg) together
    steep = synthetic.dome(radius=30.0, cap=30.0, rings=4, step=1.0)
    fixed = dataclasses.replace(cell, placement=dataclasses.replace(cell.placement, search=False))
    with pytest.raises(InputError) as err:
        choose_placement(Reach(fixed), steep)
    text = str(err.value)
    assert "unreachable" in text and "waypoint" in text
    # what is wrong and what to change in the cell file
    assert any(r in text for r in ("out of reach", "collision", "joint limit", "singularity"))
    assert "[tank]" in text or "[tool]" in text or "[robot]" in text


def test_out_of_reach_tank_is_refused(cell: CellConfig, lines_tp: Toolpath) -> None:
    far_tank = dataclasses.replace(cell.tank, floor_center_mm=(1400.0, 0.0, 8.0))
    far = dataclasses.replace(cell, tank=far_tank,
                              placement=dataclasses.replace(cell.placement, search=False))
    with pytest.raises(InputError, match="out of reach"):
        choose_placement(Reach(far), lines_tp)


def test_model_taller_than_gel_is_refused(cell: CellConfig) -> None:
    tall = synthetic.spiral(turns=2.0, radius=20.0, height=cell.tank.gel_fill_mm)
    with pytest.raises(InputError, match="gel"):
        choose_placement(Reach(cell), tall)


def test_batched_level_search_equals_level_by_level(cell: CellConfig,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    import planner.placement as placement
    from tests.planner.test_orientation import _along_wall_case

    wall_cell, tp, model_T = _along_wall_case(cell)  # some waypoints need a lean
    reach = Reach(wall_cell)
    idx = np.arange(len(tp))
    R = model_T[:3, :3]
    p = tp.position @ R.T + model_T[:3, 3]
    t = placement.waypoint_tangents(tp.position, tp.path) @ R.T
    args = (reach, p, tp.normal @ R.T, t, tp.extrude)
    levels = placement.orientation_levels
    for repeat in range(4):  # level 0 repeated: the first reaching level moves within blocks
        monkeypatch.setattr(placement, "orientation_levels", lambda *a, k=repeat: np.concatenate(
            [np.repeat(levels(*a)[:1], k, axis=0), levels(*a)]))
        monkeypatch.setattr(placement, "SCORE_BATCH", 4096)
        batched = placement.reach_levels(*args)
        s_batched = placement.score(reach, tp, model_T, idx)
        monkeypatch.setattr(placement, "SCORE_BATCH", 1)  # one level per check
        single = placement.reach_levels(*args)
        assert np.array_equal(batched.level, single.level)
        assert np.array_equal(batched.best, single.best)
        assert np.all(batched.level >= 0) and np.any(batched.level > 1)  # beyond block 1
        assert s_batched == placement.score(reach, tp, model_T, idx)


def test_alternatives_reach_and_turn_the_job_away_from_the_best_yaw(cell: CellConfig,
                                                                     dome_tp: Toolpath) -> None:
    p = choose_placement(Reach(cell), dome_tp)
    alts = p.alternatives
    assert len(alts) >= 2
    assert all((x, y, yaw) != (*p.offset_mm[:2], p.yaw_deg) for x, y, yaw, _ in alts)

    def apart(a: float, b: float) -> float:
        return abs((a - b + 180.0) % 360.0 - 180.0)

    # the leading alternatives lie at least YAW_APART_DEG from the best and from each other
    lead = []
    for a in alts:
        if all(apart(a[2], y) >= YAW_APART_DEG for y in [p.yaw_deg, *[b[2] for b in lead]]):
            lead.append(a)
        else:
            break
    assert len(lead) >= 2
    clear = [a[3] for a in lead]
    assert clear == sorted(clear, reverse=True)


def test_a_blocked_entry_is_replanned_at_another_yaw(cell: CellConfig) -> None:
    # a cup's rounded bottom under a 150 mm part: where the job starts on the far side, its
    # nozzle leans 40 deg towards the robot and the line to plunge along leaves the arm's
    # reach; the searched placement starts it there, another yaw does not
    tp = synthetic.rings(45.0, [0.0, 150.0], [40.0, 0.0], step=1.0)
    searched = choose_placement(Reach(fit_gel(cell, tp)), tp)
    blocked = plan(tp, cell, placement=searched)
    assert blocked.report["entry"]["status"] != "ok"
    result = plan(tp, cell)
    assert result.status == "ok"
    assert result.report["entry"]["status"] == "ok" and result.report["exit"]["status"] == "ok"
    assert result.report["placement"]["replanned"] >= 1
    assert result.placement.yaw_deg != searched.yaw_deg


def test_an_unreachable_waypoint_is_replanned_at_another_placement(
        cell: CellConfig, monkeypatch: pytest.MonkeyPatch) -> None:
    # the placement score checks a sample of the waypoints: where the plan then finds one out
    # of reach (a lone waypoint at a steep edge), the next of the search's placements is tried
    import planner.plan as plan_module

    tp = synthetic.rings(45.0, [0.0, 30.0], [0.0, 0.0], step=2.0)
    real = plan_module._plan_placed
    yaws: list[float] = []

    def first_one_refused(*args: object, **kwargs: object) -> object:
        result = real(*args, **kwargs)  # type: ignore[arg-type]
        yaws.append(result.placement.yaw_deg)
        if len(yaws) == 1:  # as if one waypoint were out of reach there
            # what `plan` alone returns for this job: ok at the searched placement, no re-plan
            assert result.status == "ok" and "replanned" not in result.report["placement"]
            result.report["unreachable"]["count"] = 1
            return dataclasses.replace(result, status=PlanStatus.UNREACHABLE)
        return result

    monkeypatch.setattr(plan_module, "_plan_placed", first_one_refused)
    result = plan(tp, cell)
    assert len(yaws) == 2 and yaws[1] != yaws[0]
    assert result.report["unreachable"]["count"] == 0
    assert result.report["placement"]["replanned"] == 1
    assert result.placement.yaw_deg == yaws[1]
