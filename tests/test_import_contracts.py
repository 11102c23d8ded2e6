"""The packages' import rules hold (docs/architecture.md, issue 24).

``lint-imports`` checks the contracts of ``[tool.importlinter]`` in pyproject.toml: the layers
core <- slicer <- planner <- sim <- mesp_cell, no library importing runtime or bus code, no
import cycle inside a package. The grimp graph it builds answers the rule no contract type
states: planner and sim take from the slicer only their inputs (the job, the model, the
extrusion profile), never its algorithms; the shared base they need is in ``core``.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import grimp

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("core", "slicer", "planner", "sim", "mesp_cell")
#: slicer modules planner and sim may import: what they receive from a job, not how it is made
SLICER_INPUTS = frozenset({
    "slicer.config",     # the job's settings (JobConfig, units)
    "slicer.mesh_io",    # the model's surface (Surface)
    "slicer.extrusion",  # the job's extrusion profile: C and the morphology model (design.md)
    "slicer.profiles",   # the bundled extrusion profiles (data files)
})
#: named exceptions: ``mesp check``'s preflight shows the critical regions a slice would fix
#: by running the slicer's own selection on the surface
SLICER_EXCEPTIONS = frozenset({
    ("planner.preflight", "slicer.critical"),
    ("planner.preflight", "slicer.operators"),
    # ... and its wall finding measures the walls against the slicer's narrowest line and
    # names a size rounded as the slicer's thin-wall refusal rounds it
    ("planner.preflight", "slicer.wall_thickness"),
    ("planner.preflight_walls", "slicer.wall_thickness"),
    ("planner.preflight_walls", "slicer.toolpath.thin_features"),
    # the normal-spike repair runs at the plan's input: in the toolpath stage it would change
    # saved toolpaths (docs/architecture.md); the printing directions the plan follows are
    # made in one place (planner.printability) for the plan and the slicing-time check
    ("planner.printability", "slicer.normals"),
    # `mesp inspect --flush` and the volume-mode planar baseline flush the waypoints first
    ("sim.baseline_prints", "slicer.toolpath.flush"),
})


def _lint_imports() -> str:
    exe = shutil.which("lint-imports") or str(Path(sys.executable).with_name("lint-imports"))
    assert Path(exe).exists(), "lint-imports is missing: pip install -e '.[dev]' (import-linter)"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get(
        "PYTHONPATH", "")])}
    run = subprocess.run([exe, "--no-cache"], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-2000:]
    return run.stdout


def test_the_import_contracts_are_kept() -> None:
    out = _lint_imports()
    assert "0 broken" in out and "BROKEN" not in out, out


def _slicer_imports_by(graph: grimp.ImportGraph, package: str) -> set[tuple[str, str]]:
    pairs = set()
    for importer in graph.find_descendants(package) | {package}:
        for imported in graph.find_modules_directly_imported_by(importer):
            if imported == "slicer" or imported.startswith("slicer."):
                pairs.add((importer, imported))
    return pairs


def test_planner_and_sim_take_only_their_inputs_from_the_slicer() -> None:
    graph = grimp.build_graph(*PACKAGES, cache_dir=None)
    used = _slicer_imports_by(graph, "planner") | _slicer_imports_by(graph, "sim")
    wrong = sorted(p for p in used if p[1] not in SLICER_INPUTS and p not in SLICER_EXCEPTIONS)
    assert not wrong, (
        "planner/sim import slicer algorithms (move the shared part to core, or pass the "
        "result in): " + ", ".join(f"{a} -> {b}" for a, b in wrong))
    stale = sorted(SLICER_EXCEPTIONS - used)
    assert not stale, f"exceptions no longer needed, delete them here: {stale}"
