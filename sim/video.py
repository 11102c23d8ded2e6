"""Dry-run video of a planned job: the twin replaying ``trajectory.npz`` with the ink laid so far.

Frames are taken every ``speedup / fps`` seconds of the print. Each shows the cell from a
camera framing the part (its surface a faint ghost, when given), the ink of every extruding
toolpath segment finished by then (capsules of the target width, coloured by layer), a
caption (print time, layer, clearance) and a timeline strip of the whole print with its
marked moments: red where the arm and tool come closer than ``low_clearance_mm`` to the
cell, orange where the arm moves an extruding segment slower than ``SLOWED`` x its toolpath
speed (``planner.flow.segment_speeds``); the caption turns the same colour while such a moment
is within the frame's interval. Written as H.264 MP4 through imageio-ffmpeg, with a contact
sheet PNG of evenly spaced frames.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from core.stages import Toolpath
from core.tolerance import tol
from planner.flow import segment_speeds
from planner.trajectory import Trajectory
from sim.as_planned import SLOWED
from sim.render import open_scene
from sim.twin import Twin

MAX_INK = 6000  # capsules drawn per frame; longer jobs draw every k-th segment of each path
RED = np.array([220, 40, 40], np.uint8)
ORANGE = np.array([245, 150, 20], np.uint8)


@dataclass(frozen=True)
class VideoResult:
    """What ``render_video`` wrote.

    Attributes:
        path, sheet: the MP4 and contact sheet PNG (None if rendering is unavailable here).
        frames: frames written. width, height: px. render_s: wall time, s.
        print_s: duration of the print shown, s. message: why nothing was written ("" if ok).
    """

    path: Path | None
    sheet: Path | None
    frames: int
    width: int
    height: int
    render_s: float
    print_s: float
    message: str

    @property
    def render_s_per_print_min(self) -> float:
        """Wall seconds of rendering per minute of print."""
        return self.render_s / max(self.print_s / 60.0, tol.floor)


@dataclass(frozen=True)
class Ink:
    """Extruding toolpath segments in print order, in the world frame.

    p0, p1: (S, 3) float64, m. radius: (S,) float64, m. rgba: (S, 4) float32.
    done_t: (S,) float64, s, when the nozzle finishes the segment. layer: (S,) int32.
    """

    p0: NDArray[np.float64]
    p1: NDArray[np.float64]
    radius: NDArray[np.float64]
    rgba: NDArray[np.float32]
    done_t: NDArray[np.float64]
    layer: NDArray[np.int32]


def waypoint_times(traj: Trajectory, n: int) -> NDArray[np.float64]:
    """(n,) s: the time the trajectory passes each toolpath waypoint."""
    wp = np.asarray(traj.waypoint)
    rows = np.flatnonzero(wp >= 0)
    t = np.full(n, np.nan)
    t[wp[rows]] = np.asarray(traj.t)[rows]
    return t


def ink_segments(toolpath: Toolpath, traj: Trajectory, max_segments: int = MAX_INK) -> Ink:
    """The extruding segments (decimated along each path to at most ``max_segments``)."""
    import matplotlib

    n = len(toolpath)
    keep = np.ones(n, bool)
    same = np.r_[toolpath.path[1:] == toolpath.path[:-1], False]
    extruding = same & toolpath.extrude & np.r_[toolpath.extrude[1:], False]
    stride = int(np.ceil(extruding.sum() / max(max_segments, 1)))
    if stride > 1:  # every stride-th waypoint of each path, its ends kept
        start = np.r_[True, toolpath.path[1:] != toolpath.path[:-1]]
        run = np.cumsum(start) - 1
        first = np.flatnonzero(start)[run]
        keep = ((np.arange(n) - first) % stride == 0) | start | np.r_[start[1:], True]
    idx = np.flatnonzero(keep)
    a, b = idx[:-1], idx[1:]
    on = (toolpath.path[a] == toolpath.path[b]) & toolpath.extrude[a] & toolpath.extrude[b]
    a, b = a[on], b[on]
    M = np.asarray(traj.base_T) @ np.asarray(traj.model_T)
    world = (toolpath.position @ M[:3, :3].T + M[:3, 3]) / 1000.0
    layers = toolpath.layer[a]
    span = max(int(toolpath.layer.max()) if n else 0, 1)
    rgba = np.asarray(matplotlib.colormaps["viridis"](layers / span), np.float32)
    t = waypoint_times(traj, n)
    return Ink(world[a], world[b], 0.5 * toolpath.width[a] / 1000.0, rgba, t[b],
               layers.astype(np.int32))


def work_view(traj: Trajectory, toolpath: Toolpath) -> tuple[NDArray[np.float64], float]:
    """(look-at point (3,) m in the world, extent m) of a camera framing the part."""
    M = np.asarray(traj.base_T) @ np.asarray(traj.model_T)
    lo, hi = toolpath.position.min(axis=0), toolpath.position.max(axis=0)
    centre = (M[:3, :3] @ (0.5 * (lo + hi)) + M[:3, 3]) / 1000.0
    extent = max(float(np.linalg.norm(hi - lo)) / 1000.0, 0.08)
    return centre + np.array([0.0, 0.0, 0.25 * extent]), 0.75 * extent


def frame_times(duration_s: float, speedup: float, fps: float,
                max_frames: int | None = None) -> NDArray[np.float64]:
    """(F,) s: print times of the frames, the last frame at the end of the print."""
    step = speedup / fps
    count = max(2, int(np.ceil(duration_s / step)) + 1)
    if max_frames is not None:
        count = min(count, max(2, max_frames))
    return np.linspace(0.0, duration_s, count)


def marks(frames_t: NDArray[np.float64], traj: Trajectory, toolpath: Toolpath,
          clearance: NDArray[np.float64] | None,
          low_clearance_mm: float) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Per frame (F,): a low-clearance moment, a slowed extruding segment in the interval
    since the previous frame."""
    low = np.zeros(len(frames_t), bool)
    if clearance is not None and len(clearance) == len(traj):
        hit = np.asarray(traj.t)[np.isfinite(clearance) & (clearance < low_clearance_mm)]
        low[_frame_of(frames_t, hit)] = True
    speeds = segment_speeds(toolpath, traj)
    t_wp = waypoint_times(traj, len(toolpath))
    slowed = (speeds.ratio < SLOWED) & toolpath.extrude[:-1] & toolpath.extrude[1:]
    slow = np.zeros(len(frames_t), bool)
    slow[_frame_of(frames_t, t_wp[:-1][slowed])] = True
    return low, slow


def _frame_of(frames_t: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray[np.intp]:
    """(K,) index of the frame showing each time ``t`` (K,) s: the first at or after it."""
    return np.minimum(np.searchsorted(frames_t, t, side="left"), len(frames_t) - 1)


def _strip(width: int, low: NDArray[np.bool_], slow: NDArray[np.bool_]) -> NDArray[np.uint8]:
    """(10, width, 3) timeline of the print: grey, orange where slowed, red where clearance
    is low."""
    strip = np.full((10, width, 3), 90, np.uint8)
    col = np.minimum((np.arange(len(low)) * width) // max(len(low), 1), width - 1)
    strip[:, col[slow]] = ORANGE
    strip[:, col[low]] = RED
    return strip


def _caption(img: NDArray[np.uint8], text: str, colour: NDArray[np.uint8] | None) -> None:
    """Write ``text`` on a banner at the top of ``img`` (in place)."""
    from PIL import Image, ImageDraw

    img[:22] = colour if colour is not None else np.array([30, 30, 30], np.uint8)
    pil = Image.fromarray(img[:22])
    ImageDraw.Draw(pil).text((6, 5), text, fill=(255, 255, 255))
    img[:22] = np.asarray(pil)


def _clock(seconds: float) -> str:
    s = round(seconds)
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}"


def render_video(twin: Twin, traj: Trajectory, toolpath: Toolpath, path: Path, *,
                 speedup: float = 60.0, fps: float = 24.0, width: int = 640, height: int = 480,
                 clearance: NDArray[np.float64] | None = None, low_clearance_mm: float = 5.0,
                 max_frames: int | None = None, sheet: Path | None = None,
                 part: tuple[np.ndarray, np.ndarray] | None = None) -> VideoResult:
    """Render the dry run of ``traj`` to ``path`` (MP4) and a contact sheet (see module doc).

    clearance: (M,) float64, mm, per trajectory sample (``PlanResult.clearance``), or None.
    part: the model's surface (vertices (V, 3) float64 mm in the model frame, faces (F, 3)),
    drawn as a faint ghost, or None.
    width and height are rounded up to multiples of 16 (what H.264 encoders expect).
    """
    import imageio.v2 as imageio

    width, height = 16 * -(-width // 16), 16 * -(-height // 16)
    start = time.perf_counter()
    ink = ink_segments(toolpath, traj)
    ghost = None
    if part is not None:
        M = np.asarray(traj.base_T) @ np.asarray(traj.model_T)
        ghost = ((np.asarray(part[0]) @ M[:3, :3].T + M[:3, 3]) / 1000.0, np.asarray(part[1]))
    scene, why = open_scene(twin, width, height, max_geom=len(ink.done_t) + 1000, fast=True,
                            part=ghost)
    if scene is None:
        return VideoResult(None, None, 0, width, height, 0.0, traj.duration_s, why)
    frames_t = frame_times(traj.duration_s, speedup, fps, max_frames)
    low, slow = marks(frames_t, traj, toolpath, clearance, low_clearance_mm)
    strip = _strip(width, low, slow)
    scene.frame_work(*work_view(traj, toolpath))
    q = np.stack([np.interp(frames_t, traj.t, traj.q[:, j]) for j in range(6)], axis=1)
    done = np.searchsorted(ink.done_t, frames_t, side="right")
    t_wp = waypoint_times(traj, len(toolpath))
    last_wp = np.clip(np.searchsorted(t_wp, frames_t, side="right") - 1, 0, len(toolpath) - 1)
    layers = int(toolpath.layer.max()) + 1 if len(toolpath) else 0
    frame_clear = _interval_min(frames_t, traj, clearance)
    picks = set(np.linspace(0, len(frames_t) - 1, min(12, len(frames_t))).astype(int).tolist())
    kept: list[tuple[float, NDArray[np.uint8], str]] = []
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    writer = imageio.get_writer(str(path), fps=fps, codec="libx264", quality=6,
                                macro_block_size=16, ffmpeg_log_level="error")
    try:
        for f, tf in enumerate(frames_t):
            k = int(done[f])
            extra = [(ink.p0[i], ink.p1[i], float(ink.radius[i]), ink.rgba[i])
                     for i in range(k)]
            img = scene.draw(q[f], extra)
            text = (f"{_clock(tf)} / {_clock(traj.duration_s)}  x{speedup:g}   layer "
                    f"{int(toolpath.layer[last_wp[f]]) + 1}/{layers}")
            if np.isfinite(frame_clear[f]):
                text += f"   clearance {frame_clear[f]:.1f} mm"
            text += "   LOW CLEARANCE" if low[f] else ""
            text += "   SLOWED" if slow[f] else ""
            _caption(img, text, RED if low[f] else ORANGE if slow[f] else None)
            img[-10:] = strip
            img[-14:, min(width - 2, int(f * width / len(frames_t))):][:, :2] = 255
            writer.append_data(img)
            if f in picks:
                kept.append((float(tf), img, "tab:red" if low[f] else
                             "tab:orange" if slow[f] else "black"))
    finally:
        writer.close()
        scene.close()
    sheet_path = contact_sheet(kept, Path(sheet) if sheet else path.with_suffix(".png"))
    return VideoResult(path, sheet_path, len(frames_t), width, height,
                       time.perf_counter() - start, traj.duration_s, "")


def _interval_min(frames_t: NDArray[np.float64], traj: Trajectory,
                  clearance: NDArray[np.float64] | None) -> NDArray[np.float64]:
    """(F,) mm: the smallest clearance in each frame's interval (nan without clearances)."""
    if clearance is None or len(clearance) != len(traj):
        return np.full(len(frames_t), np.nan)
    c = np.where(np.isfinite(clearance), clearance, np.inf)
    frame = _frame_of(frames_t, np.asarray(traj.t))
    low = np.full(len(frames_t), np.inf)
    np.minimum.at(low, frame, c)
    return np.where(np.isfinite(low), low, np.nan)


def contact_sheet(frames: list[tuple[float, NDArray[np.uint8], str]], path: Path) -> Path:
    """Save up to 12 frames (time s, image, title colour) in a grid with a legend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    cols = min(4, max(1, len(frames)))
    rows = -(-len(frames) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.0 * cols, 3.2 * rows + 0.6), squeeze=False)
    for ax in axes.ravel():
        ax.set_axis_off()
    for ax, (t, img, colour) in zip(axes.ravel(), frames, strict=False):
        ax.imshow(img[22:-14])
        ax.set_title(f"t = {_clock(t)}", fontsize=10, color=colour)
    from matplotlib.colors import to_hex

    red, orange = to_hex(tuple(RED / 255)), to_hex(tuple(ORANGE / 255))
    fig.legend(handles=[Patch(color=red, label="clearance below the video's threshold"),
                        Patch(color=orange, label=f"arm below {SLOWED:.0%} of the "
                              "toolpath speed while extruding"),
                        Patch(color="white", label="ink coloured by layer (viridis: first "
                              "dark, last yellow); faint white: the part's surface")],
               loc="lower center", ncol=3, fontsize=9, facecolor="0.9")
    fig.suptitle("dry run on the twin: contact sheet (title coloured where a moment is marked "
                 "since the frame before)")
    fig.tight_layout(rect=(0.0, 0.05, 1.0, 1.0))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
