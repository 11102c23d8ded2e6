"""The offscreen GL backend is picked before mujoco loads: EGL, else OSMesa, else none."""

from __future__ import annotations

import sys

import pytest

from sim import gl


@pytest.fixture
def fresh(monkeypatch: pytest.MonkeyPatch) -> pytest.MonkeyPatch:
    monkeypatch.delenv("MUJOCO_GL", raising=False)
    monkeypatch.delitem(sys.modules, "mujoco", raising=False)  # as before the first import
    return monkeypatch


@pytest.mark.parametrize(("libraries", "chosen"), [
    ({"EGL", "OSMesa"}, "egl"), ({"OSMesa"}, "osmesa"), (set(), "")])
def test_first_available_backend_is_chosen(fresh: pytest.MonkeyPatch, libraries: set[str],
                                           chosen: str) -> None:
    fresh.setattr(gl.ctypes.util, "find_library",
                  lambda name: f"lib{name}.so" if name in libraries else None)
    assert gl.choose_gl() == chosen
    assert gl.os.environ.get("MUJOCO_GL", "") == chosen


def test_a_backend_the_user_set_is_kept(fresh: pytest.MonkeyPatch) -> None:
    fresh.setenv("MUJOCO_GL", "osmesa")
    fresh.setattr(gl.ctypes.util, "find_library", lambda name: f"lib{name}.so")
    assert gl.choose_gl() == "osmesa"
