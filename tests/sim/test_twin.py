"""The MuJoCo twin: FK agreement with the planner, replay tracking, clean render skip."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from planner import kinematics as kin
from planner.cell import CellConfig, load_cell
from planner.plan import plan
from sim.twin import Twin
from tests.planner import synthetic


@pytest.fixture(scope="module")
def cell() -> CellConfig:
    return load_cell()


@pytest.fixture(scope="module")
def twin(cell: CellConfig) -> Twin:
    return Twin(cell)


def test_twin_tcp_matches_planner_fk(twin: Twin, cell: CellConfig) -> None:
    q = np.random.default_rng(0).uniform(-np.pi, np.pi, (100, 6))
    tool = cell.tool.tool_T.copy()
    tool[:3, 3] /= 1000.0
    ours = kin.fk(q, tool)[:, :3, 3] * 1000.0
    assert np.abs(twin.fk_mm(q) - ours).max() < 0.1
    twin.set_q(q[0])
    T = twin.tcp_pose()
    assert np.allclose(T[:3, :3], kin.fk(q[0], tool)[:3, :3], atol=1e-9)


def test_replay_tracks_the_tcp(twin: Twin, cell: CellConfig) -> None:
    tp = synthetic.lines(n_lines=2, length=15.0)
    result = plan(tp, cell)
    rep = twin.replay(result.trajectory, record_every=5)
    assert rep.t[-1] >= result.trajectory.duration_s - 0.01
    assert rep.error_mm.max() < 0.5


def test_render_png_or_clean_skip(twin: Twin, cell: CellConfig, tmp_path: Path) -> None:
    from sim.render import render_png

    out = render_png(twin, np.radians(cell.robot.home_deg), tmp_path / "cell.png",
                     width=160, height=120)
    if out.path is None:
        assert "MUJOCO_GL" in out.message
    else:
        assert out.path.is_file() and out.path.stat().st_size > 1000
