"""Offscreen PNG snapshots of the twin, where an OpenGL backend exists.

MuJoCo picks its GL backend from ``MUJOCO_GL`` (egl or osmesa on a headless machine) when it is
first imported. Without a working backend ``render_png`` returns a ``RenderResult`` whose
``path`` is None and whose ``message`` says why: it never raises for a missing display.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sim.twin import GL_PROBLEM, Twin, mujoco


@dataclass(frozen=True)
class RenderResult:
    """Outcome of a render request.

    Attributes:
        path: the PNG written, or None if rendering is unavailable here.
        message: empty on success, else the reason (and how to enable rendering).
    """

    path: Path | None
    message: str


def render_png(twin: Twin, q: np.ndarray, path: Path, width: int = 640,
               height: int = 480) -> RenderResult:
    """Render the cell at joint angles ``q`` (6,) rad to ``path`` (PNG)."""
    backend = os.environ.get("MUJOCO_GL", "")
    if GL_PROBLEM:
        return RenderResult(
            None, f"offscreen rendering unavailable: {GL_PROBLEM}; install that backend or "
            "set MUJOCO_GL=egl",
        )
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # GLFW warns about a missing display first
            renderer = mujoco.Renderer(twin.model, height=height, width=width)
    except Exception as exc:  # any GL failure means "no rendering here", never a crash
        return RenderResult(
            None,
            f"offscreen rendering unavailable (MUJOCO_GL={backend or 'unset'}: {exc}); "
            "set MUJOCO_GL=egl or MUJOCO_GL=osmesa before starting",
        )
    try:
        twin.set_q(q)
        camera = mujoco.MjvCamera()
        camera.lookat[:] = twin.model.geom("tank_floor").pos + np.array([-0.15, 0.0, 0.1])
        camera.distance = 1.6
        camera.azimuth = 135.0
        camera.elevation = -25.0
        renderer.update_scene(twin.data, camera=camera)
        pixels = renderer.render()
    except Exception as exc:
        return RenderResult(None, f"offscreen rendering failed ({exc})")
    finally:
        renderer.close()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    plt.imsave(path, pixels)
    return RenderResult(path, "")
