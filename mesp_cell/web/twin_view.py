"""The console's view of the twin: the cell drawn by MuJoCo at the pose the robot reports.

During a dry run on the twin (and beside the real arm) the page shows the arm and nozzle in
the tank as the robot node reports them on the bus. Frames are rendered on request, on one
thread of their own (an offscreen GL context belongs to the thread that made it), at most one
per ``MIN_INTERVAL_S``: a page polling faster gets the last frame again, so no number of
browsers can load the console beyond one render a second.
"""

from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

MIN_INTERVAL_S = 1.0  # at most one render per second, whoever asks
SIZE_PX = (480, 360)  # width, height of a frame
VIEW_EXTENT_M = 0.5  # what the camera frames around the tank, m


class TwinView:
    """Renders the twin of ``cell_file`` (None = the bundled cell) at a reported pose."""

    def __init__(self, cell_file: Path | None, size: tuple[int, int] = SIZE_PX) -> None:
        self.cell_file = cell_file
        self.size = size
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="twin-view")
        self._lock = threading.Lock()
        self._scene: Any = None
        self._why = ""
        self._last: tuple[float, bytes] | None = None

    def frame(self, q_deg: tuple[float, ...] | np.ndarray) -> tuple[bytes | None, str]:
        """(PNG bytes, "") of the cell at joint angles ``q_deg`` (6,) deg, or (None, why the
        twin cannot be drawn here)."""
        with self._lock:
            now = time.monotonic()
            if self._last is not None and now - self._last[0] < MIN_INTERVAL_S:
                return self._last[1], ""
            png, why = self._pool.submit(self._render, np.radians(np.asarray(q_deg, float))
                                         ).result()
            if png is not None:
                self._last = (now, png)
            return png, why

    def _render(self, q_rad: np.ndarray) -> tuple[bytes | None, str]:
        """On the view's own thread: open the scene once, draw, encode."""
        if self._scene is None and not self._why:
            from planner.cell import load_cell
            from sim.render import open_scene
            from sim.twin import Twin

            try:
                twin = Twin(load_cell(self.cell_file))
            except Exception as exc:  # a bad cell file: say so on every request
                name = self.cell_file or "the bundled cell"
                self._why = f"the twin of {name} cannot be built ({exc})"
                return None, self._why
            self._scene, self._why = open_scene(twin, *self.size, fast=True)
            if self._scene is not None:  # the tank and the arm's lower links above it
                floor = np.asarray(self._scene.model.geom("tank_floor").pos, float)
                self._scene.frame_work(floor + np.array([0.0, 0.0, 0.2]), VIEW_EXTENT_M)
        if self._scene is None:
            return None, self._why
        import imageio.v3 as iio

        pixels = self._scene.draw(q_rad)
        return bytes(iio.imwrite("<bytes>", pixels, extension=".png")), ""

    def close(self) -> None:
        """Release the GL context on its thread, then the thread."""
        if self._scene is not None:
            self._pool.submit(self._scene.close).result()
            self._scene = None
        self._pool.shutdown(wait=True)
