"""Property-based fuzzing of every input boundary with Hypothesis.

Each property mutates a valid input (a mesh file, a job/cell/launch TOML, G-code, a
toolpath.npz) at random and asserts what a user must see: either the input is still valid and
accepted, or it is refused with exit 2 and one line ``mesp: error: ...; <fix>`` (an
``InputError`` at the library boundary), never a traceback, a library's exit, a hang or a
stray or partial file. Meshes, job and cell files go through ``mesp job submit`` (it loads
and checks all three without starting a cell); launch files, G-code and stage files through
the functions that read them (a valid launch file would start processes, a valid toolpath
minutes of planning). Counts per kind are printed at the end of the session.
"""

from __future__ import annotations

import contextlib
import math
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w
from hypothesis import given
from hypothesis import strategies as st

from core.artifacts import save_npz
from core.errors import InputError
from core.stages import Toolpath
from planner.cell import default_cell_data
from sim.gcode import parse_gcode
from slicer.config import default_data
from tests.fuzz import fixtures
from tests.fuzz.harness import COUNTS, TIME_LIMIT_S, _alarm, judge

WEIRD_NUMBERS = st.sampled_from([math.nan, math.inf, -math.inf, 0.0, -1.0, 1e-300, 1e300,
                                 -1e300, 1e-9, 1e9, 2**63, -(2**63), 0.5, 3.0])
WEIRD_TOKENS = st.sampled_from(["nan", "inf", "-inf", "1e400", "-1", "0", "", "x", "1e30",
                                "99999999999999999999", "0x10", "1,5", "-0", "3.5.5"])


@contextlib.contextmanager
def _fresh() -> Iterator[Path]:
    """A directory of its own for one example, removed afterwards."""
    with tempfile.TemporaryDirectory(prefix="mesp-fuzz-") as name:
        yield Path(name)


# -- meshes through `mesp job submit` ------------------------------------------------------
_OBJ = ("".join(f"v {x} {y} {z}\n" for x in (0, 20) for y in (0, 20) for z in (0, 20))
        + "f 1 2 4 3\nf 5 7 8 6\nf 1 5 6 2\nf 3 4 8 7\nf 1 3 7 5\nf 2 6 8 4\n")
_PLY = ("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
        "property float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n20 0 0\n0 20 0\n0 0 20\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n")
_STL = ("solid t\n" + "".join(
    f"facet normal 0 0 0\nouter loop\nvertex {a}\nvertex {b}\nvertex {c}\nendloop\nendfacet\n"
    for a, b, c in [("0 0 0", "0 20 0", "20 0 0"), ("0 0 0", "20 0 0", "0 0 20"),
                    ("0 0 0", "0 0 20", "0 20 0"), ("20 0 0", "0 20 0", "0 0 20")])
        + "endsolid t\n")
_VTK = ("# vtk DataFile Version 2.0\nt\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 double\n"
        "0 0 0\n20 0 0\n0 20 0\n0 0 20\nCELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n10\n")
MESHES = {".obj": _OBJ, ".ply": _PLY, ".stl": _STL, ".vtk": _VTK}


@st.composite
def mutated_text(draw: st.DrawFn, text: str) -> bytes:
    """``text`` with 1-4 random edits: a token replaced, a line dropped or doubled, the
    file cut short, random bytes put in."""
    lines = text.splitlines(keepends=True)
    for _ in range(draw(st.integers(1, 4))):
        i = draw(st.integers(0, len(lines) - 1))
        kind = draw(st.sampled_from(["token", "drop", "double", "cut", "bytes"]))
        if kind == "token":
            words = lines[i].split() or [""]
            j = draw(st.integers(0, len(words) - 1))
            words[j] = draw(WEIRD_TOKENS)
            lines[i] = " ".join(words) + "\n"
        elif kind == "drop" and len(lines) > 1:
            del lines[i]
        elif kind == "double":
            lines.insert(i, lines[i])
        elif kind == "cut":
            lines = [*lines[:i], lines[i][:draw(st.integers(0, len(lines[i])))]]
        else:
            lines.insert(i, draw(st.binary(min_size=1, max_size=40)).decode("latin-1"))
    return "".join(lines).encode("latin-1")


@given(st.data())
def test_mutated_meshes_are_accepted_or_refused_in_one_line(data: st.DataObject) -> None:
    suffix = data.draw(st.sampled_from(sorted(MESHES)))
    body = data.draw(mutated_text(MESHES[suffix]))
    with _fresh() as tmp:
        model = tmp / f"model{suffix}"
        model.write_bytes(body)
        judge(["job", "submit", str(model)], tmp, out_dirs=("home",), kind="mesh")


# -- job and cell files through `mesp job submit` ------------------------------------------
def _leaves(data: dict[str, Any], prefix: str = "") -> list[tuple[str, ...]]:
    out: list[tuple[str, ...]] = []
    for key, value in data.items():
        if isinstance(value, dict):
            out += [(key, *rest) for rest in _leaves(value)]
        else:
            out.append((key,))
    return out


VALUES = st.one_of(WEIRD_NUMBERS, st.integers(-(2**40), 2**40), st.text(max_size=8),
                   st.booleans(), st.lists(WEIRD_NUMBERS, max_size=7),
                   st.dictionaries(st.text(min_size=1, max_size=4), st.integers(), max_size=2))


@st.composite
def mutated_table(draw: st.DrawFn, defaults: dict[str, Any]) -> dict[str, Any]:
    """1-3 keys of ``defaults`` (or a made-up one) set to random values, as a user file."""
    leaves = _leaves(defaults)
    out: dict[str, Any] = {}
    for _ in range(draw(st.integers(1, 3))):
        keys = draw(st.sampled_from(leaves))
        if draw(st.integers(0, 9)) == 0:
            keys = (*keys[:-1], draw(st.text("abcxyz_", min_size=1, max_size=6)))
        table = out
        for k in keys[:-1]:
            table = table.setdefault(k, {})
        table[keys[-1]] = draw(VALUES)
    return out


@given(mutated_table(default_data()))
def test_mutated_job_files_are_accepted_or_refused_in_one_line(table: dict[str, Any]) -> None:
    with _fresh() as tmp:
        job = tmp / "job.toml"
        job.write_text(tomli_w.dumps(table))
        model = fixtures.cube_stl(tmp / "cube.stl")
        judge(["job", "submit", str(model), "--job", str(job)], tmp, out_dirs=("home",), kind="job")


@given(mutated_table({k: v for k, v in default_cell_data().items() if k != "tool"}))
def test_mutated_cell_files_are_accepted_or_refused_in_one_line(table: dict[str, Any]) -> None:
    with _fresh() as tmp:
        cell = tmp / "cell.toml"
        cell.write_text(tomli_w.dumps(table))
        model = fixtures.cube_stl(tmp / "cube.stl")
        judge(["job", "submit", str(model), "--cell", str(cell)], tmp, out_dirs=("home",),
              kind="cell")


# -- readers called directly ----------------------------------------------------------------
def _accepted_or_input_error(kind: str, call: Any) -> Any:
    """Run ``call``: a value or an ``InputError`` (one line with a fix); anything else fails."""
    COUNTS[f"{kind}: run"] += 1
    try:
        with _alarm(TIME_LIMIT_S):
            return call()
    except InputError as exc:
        COUNTS[f"{kind}: refused"] += 1
        assert "\n" not in exc.one_line() and exc.fix, exc.one_line()
        return None
    except BaseException:
        COUNTS[f"{kind}: failed"] += 1
        raise


@given(mutated_text(fixtures.LAUNCH_OK))
def test_mutated_launch_files_are_accepted_or_refused_in_one_line(body: bytes) -> None:
    from mesp_cell.launch_file import load_launch

    with _fresh() as tmp:
        path = tmp / "launch.toml"
        path.write_bytes(body)
        spec = _accepted_or_input_error("launch", lambda: load_launch(path))
        if spec is not None:
            for proc in spec.processes:
                assert math.isfinite(proc.heartbeat_timeout) and proc.max_restarts >= 0


GCODE_WORDS = st.tuples(st.sampled_from("GXYZEFIJM"), st.one_of(
    st.floats(allow_nan=False, allow_infinity=False, width=64), WEIRD_NUMBERS.filter(
        math.isfinite), st.integers(-3, 3)))
# A printing move: mostly sane numbers, so that many programs are valid and get converted.
SANE = st.floats(0.0, 50.0, allow_nan=False)
PRINT_MOVE = st.tuples(SANE, SANE, st.floats(0.0, 2.0), st.floats(0.0, 0.5)).map(
    lambda m: [("G", 1), ("X", m[0]), ("Y", m[1]), ("Z", m[2]), ("E", m[3])])


@given(st.lists(st.one_of(st.lists(GCODE_WORDS, min_size=1, max_size=5), PRINT_MOVE),
                min_size=1, max_size=30))
def test_random_gcode_is_parsed_or_refused_in_one_line(program: list[list[Any]]) -> None:
    text = "G21\nG90\nM83\n" + "".join(
        " ".join(f"{k}{v:.6g}" if isinstance(v, float) else f"{k}{v}" for k, v in line) + "\n"
        for line in program)
    toolpath = _accepted_or_input_error("gcode", lambda: parse_gcode(text))
    if toolpath is not None:
        assert toolpath.check() == ""
        for name in ("position", "height", "width", "speed"):
            assert np.all(np.isfinite(getattr(toolpath, name)))


@st.composite
def mutated_toolpath(draw: st.DrawFn) -> dict[str, np.ndarray]:
    arrays = fixtures.toolpath_arrays(draw(st.integers(0, 12)))
    for _ in range(draw(st.integers(1, 3))):
        name = draw(st.sampled_from(sorted(arrays)))
        arr = arrays[name].copy()
        kind = draw(st.sampled_from(["value", "shape", "dtype", "drop"]))
        if kind == "value" and arr.size:
            i = draw(st.integers(0, len(arr) - 1))
            value = draw(WEIRD_NUMBERS)
            if arr.dtype.kind == "b":
                value = bool(value)
            elif arr.dtype.kind in "iu":  # the nearest whole number the dtype holds
                info = np.iinfo(arr.dtype)
                value = int(min(max(value, info.min), info.max)) if math.isfinite(value) else 0
            arr[i] = value
        elif kind == "shape":
            arr = arr[: draw(st.integers(0, len(arr)))]
        elif kind == "dtype":
            arr = arr.astype(draw(st.sampled_from([np.float32, np.int64, np.bool_, np.uint8])))
        elif kind == "drop":
            del arrays[name]
            continue
        arrays[name] = arr
    return arrays


@given(mutated_toolpath())
def test_mutated_toolpaths_load_valid_or_refused_in_one_line(
        arrays: dict[str, np.ndarray]) -> None:
    with _fresh() as tmp:
        save_npz(tmp / Toolpath.FILE, arrays)
        toolpath = _accepted_or_input_error("toolpath.npz", lambda: Toolpath.load(tmp))
        if toolpath is not None:
            assert toolpath.check() == "" and toolpath.extrude.any()
            assert np.all(np.isfinite(toolpath.position)) and toolpath.speed.min() > 0
