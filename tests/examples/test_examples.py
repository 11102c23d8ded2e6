"""The committed example models: closed, of the documented size, and what the script writes."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from slicer.config import load_job
from slicer.mesh_io import load_surface

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def _script() -> ModuleType:
    spec = importlib.util.spec_from_file_location("make_examples", EXAMPLES / "make_examples.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


MAKE = _script()
NAMES = sorted(MAKE.MODELS)


def test_every_model_has_a_file_and_a_job() -> None:
    assert set(NAMES) == {"socket", "aorta", "actuator", "membrane", "cube", "hemisphere"}
    for name in NAMES:
        assert (EXAMPLES / f"{name}.stl").is_file(), name
        assert (EXAMPLES / f"{name}.toml").is_file(), name


@pytest.mark.parametrize("name", NAMES)
def test_committed_file_is_what_the_script_writes(name: str) -> None:
    generated = MAKE.stl_bytes(MAKE.MODELS[name]())
    assert (EXAMPLES / f"{name}.stl").read_bytes() == generated
    assert (EXAMPLES / f"{name}.toml").read_text() == MAKE.JOBS[name]


@pytest.mark.parametrize("name", NAMES)
def test_model_is_closed_sized_and_small(name: str) -> None:
    surface = load_surface(EXAMPLES / f"{name}.stl")
    assert surface.notes == (), "a bundled model needs no repair"
    assert surface.volume_mm3 > 0
    assert surface.bbox_mm == pytest.approx(MAKE.SIZES_MM[name], abs=0.05)
    assert float(surface.vertices[:, 2].min()) == pytest.approx(0.0, abs=1e-4)
    assert len(surface.faces) <= 12_000


@pytest.mark.parametrize("name", NAMES)
def test_job_file_loads(name: str) -> None:
    job = load_job(EXAMPLES / f"{name}.toml")
    assert 0.3 <= job.slicing.layer_height_mm <= 1.2
    assert job.slicing.selectors


def test_cavities_and_tube_topology() -> None:
    import trimesh

    def shells(name: str) -> tuple[int, int]:
        mesh = trimesh.load_mesh(EXAMPLES / f"{name}.stl")
        return len(mesh.split(only_watertight=False)), int(mesh.euler_number)

    assert shells("actuator") == (2, 4)  # the block and one closed air-chamber chain
    assert shells("membrane") == (2, 4)  # plate with dome and the closed cavity
    assert shells("aorta") == (1, 0)  # one tube: a torus-like shell (genus 1)
    assert shells("socket") == (1, 2)  # a cup: one sphere-like shell


def test_socket_rim_is_a_saddle() -> None:
    surface = load_surface(EXAMPLES / "socket.stl")
    v = surface.vertices
    top = v[v[:, 2] > 150.0]
    angle = np.arctan2(top[:, 1], top[:, 0])
    high = top[np.abs(np.cos(2 * angle)) > 0.99]
    # The rim rises on the x sides and dips on the y sides: 20 mm between them.
    along_x = high[np.abs(high[:, 0]) > np.abs(high[:, 1])][:, 2].max()
    along_y = high[np.abs(high[:, 1]) > np.abs(high[:, 0])][:, 2].max()
    assert along_x - along_y == pytest.approx(20.0, abs=0.5)


def test_the_membrane_is_planned_in_the_tray_and_the_others_in_the_bundled_cell() -> None:
    from mesp_cell.commands.demo import _example
    from planner.cell import load_cell

    ex = _example("membrane")
    assert ex.cell is not None and ex.cell.is_file()
    tray, bundled = load_cell(ex.cell), load_cell()
    # only the tank changes: the same arm, tool and limits plan for it
    assert tray.tank.inner_size_mm[2] < 0.4 * bundled.tank.inner_size_mm[2]
    assert tray.tool == bundled.tool and tray.robot == bundled.robot
    # deep enough for the part: 28 mm, lifted by the placement, under the gel cover
    height = 28.0 + bundled.placement.offset_mm[2] + bundled.tank.gel_cover_mm
    assert tray.tank.gel_fill_mm >= height
    assert ex.job is not None
    assert load_job(ex.job).slicing.layer_height_mm == pytest.approx(0.62)
    for name in NAMES:
        if name != "membrane":
            assert _example(name).cell is None, name
