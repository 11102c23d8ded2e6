"""Shared pytest setup: a non-interactive matplotlib backend for figure tests, MuJoCo's
offscreen GL backend picked before any test imports mujoco (render and video tests), the
tet-mesh cache (slicer/tet_cache.py) in a folder of this test session, not the user's ~/.cache,
and the files holding a ``slow`` test collected first.

Why slow files first: ``--dist loadfile`` hands whole files to the workers in collection order
(``--no-loadscope-reorder``; xdist's own reorder puts files with many tests first, so a long
file of one test came last and one worker ran it alone while the other sat idle)."""

from __future__ import annotations

import os
import shutil
import tempfile

import pytest

from sim.gl import choose_gl

os.environ.setdefault("MPLBACKEND", "Agg")
#: the session's tet-mesh cache, made here (the xdist workers inherit it) and removed at the end
_CACHE_MADE = "" if "MESP_CACHE_DIR" in os.environ else tempfile.mkdtemp(prefix="mesp-test-cache-")
os.environ.setdefault("MESP_CACHE_DIR", _CACHE_MADE)
choose_gl()


def slow_files_first(items: list[pytest.Item]) -> None:
    """Reorder ``items`` in place: every file holding a test marked ``slow`` before the others,
    each file's tests kept together and in their order (a stable sort)."""
    slow = {item.path for item in items if item.get_closest_marker("slow") is not None}
    items.sort(key=lambda item: item.path not in slow)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    slow_files_first(items)


def pytest_unconfigure(config: pytest.Config) -> None:
    """The session's tet-mesh cache goes with it (it was left in /tmp, one per run)."""
    if _CACHE_MADE:
        shutil.rmtree(_CACHE_MADE, ignore_errors=True)
