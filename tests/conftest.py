"""Shared pytest setup: a non-interactive matplotlib backend for figure tests, MuJoCo's
offscreen GL backend picked before any test imports mujoco (render and video tests), and the
tet-mesh cache (slicer/tet_cache.py) in a folder of this test session, not the user's ~/.cache."""

import os
import tempfile

from sim.gl import choose_gl

os.environ.setdefault("MPLBACKEND", "Agg")
os.environ.setdefault("MESP_CACHE_DIR", tempfile.mkdtemp(prefix="mesp-test-cache-"))
choose_gl()
