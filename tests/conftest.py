"""Shared pytest setup: a non-interactive matplotlib backend for figure tests, and MuJoCo's
offscreen GL backend picked before any test imports mujoco (render and video tests)."""

import os

from sim.gl import choose_gl

os.environ.setdefault("MPLBACKEND", "Agg")
choose_gl()
