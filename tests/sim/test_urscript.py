"""URScript export: the program parses back and replays on the twin like the trajectory."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import InputError
from planner import kinematics as kin
from planner.cell import load_cell
from planner.plan import plan
from planner.trajectory import Trajectory
from sim.twin import Twin
from sim.urscript import CONTROL_PERIOD_S, ExtruderIO, parse_urscript, servo_targets, urscript
from tests.planner import synthetic


@pytest.fixture(scope="module")
def traj() -> Trajectory:
    return plan(synthetic.lines(n_lines=2, length=15.0), load_cell()).trajectory


def _fk(q: np.ndarray, tool_T: np.ndarray) -> np.ndarray:
    tool = tool_T.copy()
    tool[:3, 3] /= 1000.0
    return kin.fk(q, tool)[:, :3, 3] * 1000.0


def test_program_parses_back_onto_the_trajectory(traj: Trajectory) -> None:
    text = urscript(traj, ExtruderIO(6.57, run_output=2, rate_output=1))
    prog = parse_urscript(text, run_output=2)
    assert np.allclose(prog.tool_T, traj.tool_T, atol=1e-6)
    assert prog.t[-1] == pytest.approx(traj.duration_s, abs=CONTROL_PERIOD_S)
    steps = np.diff(prog.t)
    assert steps.min() >= CONTROL_PERIOD_S - 1e-9 and steps.max() <= 0.1 + 1e-9
    # every target is the planned pose at its time
    q_ref = np.stack([np.interp(prog.t, traj.t, traj.q[:, j]) for j in range(6)], 1)
    assert np.linalg.norm(_fk(prog.q, prog.tool_T) - _fk(q_ref, traj.tool_T), axis=1).max() < 0.01
    # the extruder runs exactly while the trajectory extrudes
    ext_ref = traj.extrude[np.searchsorted(traj.t, prog.t[:-1] + 1e-9, side="right") - 1]
    assert np.mean(prog.extrude[:-1] == ext_ref) > 0.99
    assert "set_standard_analog_out(1, 0.328500)" in text


def test_replay_of_the_program_on_the_twin_matches_within_half_a_mm(traj: Trajectory) -> None:
    prog = parse_urscript(urscript(traj, ExtruderIO(6.57)))
    rep = Twin(load_cell()).replay(prog.trajectory(traj), record_every=5)
    q_ref = np.stack([np.interp(rep.t, traj.t, traj.q[:, j]) for j in range(6)], 1)
    error = np.linalg.norm(rep.tcp - _fk(q_ref, traj.tool_T), axis=1)
    assert error.max() < 0.5


def test_long_intervals_are_split(traj: Trajectory) -> None:
    fine = servo_targets(traj, max_step_s=0.01)
    assert np.diff(fine.t).max() <= 0.01 + 1e-9
    assert len(fine.t) > len(servo_targets(traj, max_step_s=0.1).t)


def test_bad_outputs_and_programs_are_user_errors() -> None:
    with pytest.raises(InputError):
        ExtruderIO(6.57, run_output=9)
    with pytest.raises(InputError):
        ExtruderIO(rate_mm3_s=30.0, full_scale_mm3_s=20.0)
    with pytest.raises(InputError):
        parse_urscript("def p():\n  movej([0, 0, 0, 0, 0, 0])\nend\n")
