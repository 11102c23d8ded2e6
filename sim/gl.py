"""Pick MuJoCo's offscreen OpenGL backend before mujoco is first imported.

MuJoCo reads ``MUJOCO_GL`` once, at import. ``choose_gl`` keeps a value the user set, else
picks the first backend whose library this machine has: EGL (GPU or Mesa's software EGL, no
display needed), then OSMesa (pure software). Without either, rendering reports why and the
simulation still works (``sim.twin`` imports mujoco without a GL backend then).
"""

from __future__ import annotations

import ctypes.util
import os
import sys

BACKENDS = (("egl", "EGL"), ("osmesa", "OSMesa"))


def choose_gl() -> str:
    """Set ``MUJOCO_GL`` if unset and mujoco is not imported yet; returns the backend in force
    ("" if none was found)."""
    current = os.environ.get("MUJOCO_GL", "")
    if current or "mujoco" in sys.modules:
        return current
    for name, library in BACKENDS:
        if ctypes.util.find_library(library):
            os.environ["MUJOCO_GL"] = name
            return name
    return ""
