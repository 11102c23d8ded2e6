"""A print is done only with every waypoint once and the toolpath's ink within 2 %."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.artifacts import save_npz
from mesp_cell.drivers.stream import StreamPlan
from mesp_cell.nodes.print_check import VOLUME_TOLERANCE, check_print
from mesp_cell.nodes.print_ledger import Ledger
from tests.mesp_cell import synthetic

RATE = 6.0


@pytest.fixture
def job(tmp_path: Path) -> tuple[Path, StreamPlan, float]:
    synthetic.toolpath(RATE).save(tmp_path)
    n = synthetic.LAYERS * synthetic.PER_LAYER
    save_npz(tmp_path / "trajectory.npz", synthetic.trajectory_arrays(n))
    plan = StreamPlan.load(tmp_path / "trajectory.npz", 0.002)
    # the toolpath carries the ink the trajectory deposits at RATE
    ink = RATE * synthetic.LAYERS * synthetic.PER_LAYER * synthetic.STEP / synthetic.RATE_HZ
    return tmp_path, plan, ink


def ledger(job_dir: Path, plan: StreamPlan, ids: list[int]) -> None:
    led = Ledger(job_dir, fresh=True)
    led.stream(0, -1)
    for w in ids:
        led.waypoint(w, plan.sample_of_waypoint(w))
    led.close()


def test_every_waypoint_once_and_the_ink_is_done(job: tuple[Path, StreamPlan, float]) -> None:
    job_dir, plan, ink = job
    ledger(job_dir, plan, list(plan.wp_id))
    check = check_print(job_dir, plan, ink + 1.0, 1.0)  # 1 mm^3 of purge
    assert check.toolpath_mm3 == pytest.approx(ink)
    assert check.ok and check.reason == "" and check.volume_error == pytest.approx(0.0)
    assert check.report()["waypoints_printed"] == plan.wp_id.size


def test_a_missing_or_doubled_waypoint_or_wrong_ink_fails(
        job: tuple[Path, StreamPlan, float]) -> None:
    job_dir, plan, ink = job
    ids = list(plan.wp_id)
    ledger(job_dir, plan, ids[:5] + ids[6:])
    check = check_print(job_dir, plan, ink, 0.0)
    assert not check.ok and check.missing == 1 and "never reported" in check.reason
    ledger(job_dir, plan, ids[:5] + ids[4:])
    check = check_print(job_dir, plan, ink, 0.0)
    assert not check.ok and check.doubled == 1 and "twice" in check.reason
    ledger(job_dir, plan, ids)
    low = check_print(job_dir, plan, ink * (1 - 1.5 * VOLUME_TOLERANCE), 0.0)
    assert not low.ok and "-3.0 %" in low.reason and "calibrat" in low.fix
    assert check_print(job_dir, plan, ink * (1 + 0.5 * VOLUME_TOLERANCE), 0.0).ok
    assert np.isfinite(low.volume_error)
