"""Dry-run video: frames of the right size that decode, marks where the plan asks for them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.stages import Toolpath
from planner.cell import load_cell
from planner.plan import PlanResult, plan
from sim.twin import Twin
from sim.video import frame_times, ink_segments, marks, render_video
from tests.planner import synthetic


@pytest.fixture(scope="module")
def job() -> tuple[Toolpath, PlanResult]:
    tp = synthetic.lines(n_lines=2, length=15.0)
    return tp, plan(tp, load_cell())


def test_frame_times_cover_the_print_at_the_speedup() -> None:
    t = frame_times(100.0, speedup=10.0, fps=5.0)
    assert t[0] == 0.0 and t[-1] == 100.0 and len(t) == 51
    assert len(frame_times(100.0, 10.0, 5.0, max_frames=7)) == 7


def test_ink_follows_the_extruding_segments(job: tuple[Toolpath, PlanResult]) -> None:
    tp, result = job
    ink = ink_segments(tp, result.trajectory)
    assert len(ink.done_t) == len(tp) - len(np.unique(tp.path))  # one per segment of a path
    assert np.all(np.diff(ink.done_t) > 0)
    assert np.allclose(ink.radius, 0.5 * tp.width[0] / 1000.0)
    few = ink_segments(tp, result.trajectory, max_segments=10)
    assert len(few.done_t) <= 20 and few.done_t[-1] == ink.done_t[-1]


def test_marks_flag_low_clearance_frames(job: tuple[Toolpath, PlanResult]) -> None:
    tp, result = job
    traj = result.trajectory
    t = frame_times(traj.duration_s, 1.0, 2.0)
    clearance = np.full(len(traj), 50.0)
    clearance[len(traj) // 2] = 1.0
    low, slow = marks(t, traj, tp, clearance, low_clearance_mm=5.0)
    assert low.sum() == 1 and t[np.argmax(low)] >= traj.t[len(traj) // 2]
    assert slow.dtype == bool and len(slow) == len(t)


def test_video_has_the_frames_and_size_asked_and_decodes(
        job: tuple[Toolpath, PlanResult], tmp_path: Path) -> None:
    import imageio.v2 as imageio

    tp, result = job
    import trimesh

    box = trimesh.creation.box(extents=[30.0, 10.0, 5.0])  # the part's ghost, model frame
    out = render_video(Twin(load_cell()), result.trajectory, tp, tmp_path / "dry.mp4",
                       speedup=5.0, fps=4.0, width=160, height=120, max_frames=6,
                       clearance=result.clearance, part=(box.vertices, box.faces))
    if out.path is None:
        assert "MUJOCO_GL" in out.message or "libegl1" in out.message
        pytest.skip(out.message)
    assert (out.width, out.height, out.frames) == (160, 128, 6)  # height up to a multiple of 16
    reader = imageio.get_reader(str(out.path))
    frames = [np.asarray(f) for f in reader]
    reader.close()
    assert len(frames) == 6 and frames[0].shape == (128, 160, 3)
    assert frames[-1].std() > 5.0  # a picture, not a blank frame
    assert out.sheet is not None and out.sheet.stat().st_size > 10_000
    assert out.render_s > 0 and out.render_s_per_print_min > 0
