"""The catalogue of malformed inputs: one named case per mistake, for every entry point.

Each case builds its files in a fresh directory and returns the ``mesp`` argument list. Every
case must end with exit 2 and one line ``mesp: error: <problem>; <fix>`` (tests/fuzz/
test_catalogue.py in process; bench/bad_inputs.py runs each as its own process against any
checkout, which is how the before/after counts are measured).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from tests.fuzz import fixtures
from tests.fuzz.case import Case, write_file
from tests.fuzz.cases_cell import LAUNCH_CASES, SUBMIT_CASES


def _slice(model: Path, tmp: Path, *extra: str) -> list[str]:
    return ["slice", str(model), "--out", str(tmp / "out"), "--until", "tetmesh", "--quiet",
            *extra]


def _mesh(name: str, text: str | bytes) -> Callable[[Path], list[str]]:
    return lambda tmp: _slice(write_file(tmp / name, text), tmp)


_CUBE_OBJ = "".join(f"v {x} {y} {z}\n" for x in (0, 20) for y in (0, 20) for z in (0, 20))
_CUBE_F = "f 1 2 4 3\nf 5 7 8 6\nf 1 5 6 2\nf 3 4 8 7\nf 1 3 7 5\nf 2 6 8 4\n"
_PLY_HEAD = ("ply\nformat ascii 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\n"
             "property float z\nelement face {nf}\nproperty list uchar int vertex_indices\n"
             "end_header\n")
_PLY_BODY_V = "0 0 0\n20 0 0\n0 20 0\n0 0 20\n"
_PLY_BODY_F = "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"
_VTK_HEAD = "# vtk DataFile Version 2.0\nfuzz\nASCII\nDATASET UNSTRUCTURED_GRID\n"


def _vtk(points: str, n_points: int, tet: str = "4 0 1 2 3") -> str:
    return (_VTK_HEAD + f"POINTS {n_points} double\n{points}\nCELLS 1 5\n{tet}\n"
            "CELL_TYPES 1\n10\n")


MESH_CASES = [
    Case("mesh", "obj vertex with one coordinate", _mesh("a.obj", "v 1\n" + _CUBE_OBJ + _CUBE_F)),
    Case("mesh", "obj face index past the vertices", _mesh("a.obj", _CUBE_OBJ + "f 1 2 99\n")),
    Case("mesh", "obj of garbage text", _mesh("a.obj", "hello world\n\x00\x01 nonsense\n")),
    Case("mesh", "obj with nan vertex", _mesh("a.obj", _CUBE_OBJ.replace("v 0 0 0", "v nan 0 0")
                                              + _CUBE_F)),
    Case("mesh", "ply header count above the body",
         _mesh("a.ply", _PLY_HEAD.format(nv=8, nf=4) + _PLY_BODY_V + _PLY_BODY_F)),
    Case("mesh", "ply face index past the vertices",
         _mesh("a.ply", _PLY_HEAD.format(nv=4, nf=4) + _PLY_BODY_V
               + _PLY_BODY_F.replace("3 1 2 3", "3 1 2 77"))),
    Case("mesh", "ply face count below the body",
         _mesh("a.ply", _PLY_HEAD.format(nv=4, nf=2) + _PLY_BODY_V + _PLY_BODY_F)),
    Case("mesh", "ply of garbage bytes", _mesh("a.ply", b"ply\n\xff\xfe\x00garbage" * 10)),
    Case("mesh", "stl truncated binary", _mesh("a.stl", b"\0" * 80 + b"\x10\0\0\0" + b"\1" * 30)),
    Case("mesh", "stl ascii with nan", _mesh("a.stl", "solid a\nfacet normal 0 0 1\nouter loop\n"
                                             "vertex nan 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
                                             "endloop\nendfacet\nendsolid a\n")),
    Case("mesh", "stl empty file", _mesh("a.stl", b"")),
    Case("mesh", "stl of random bytes", _mesh("a.stl", bytes(range(256)) * 7)),
    Case("mesh", "model in an unreadable format (.off)", _mesh("a.off", "OFF\n0 0 0\n")),
    Case("mesh", "model a directory", lambda tmp: _slice(write_file(tmp / "d.stl" / "x", "")
                                                         .parent, tmp)),
    Case("mesh", "model missing", lambda tmp: _slice(tmp / "missing.stl", tmp)),
    Case("mesh", "cube x1e6 (read as mm)", lambda tmp: _slice(
        write_file(tmp / "a.obj", "".join(f"v {x} {y} {z}\n" for x in (0, 2e7) for y in (0, 2e7)
                                      for z in (0, 2e7)) + _CUBE_F), tmp)),
    Case("mesh", "vtk tet mesh with a nan point",
         _mesh("a.vtk", _vtk("0 0 0\n20 0 0\n0 20 0\nnan 0 20", 4))),
    Case("mesh", "vtk tet indexing past the points",
         _mesh("a.vtk", _vtk("0 0 0\n20 0 0\n0 20 0\n0 0 20", 4, "4 0 1 2 9"))),
    Case("mesh", "vtk of garbage text", _mesh("a.vtk", "# vtk DataFile Version 2.0\nnonsense\n")),
    Case("mesh", "vtu of garbage bytes", _mesh("a.vtu", b"<?xml nonsense \x00\xff" * 5)),
    Case("mesh", "vtu of plain text", _mesh("a.vtu", "not a vtu at all\n")),
    Case("mesh", "msh of garbage text", _mesh("a.msh", "$MeshFormat\n9 9 9\n$EndMeshFormat\n")),
]


def _job(text: str) -> Callable[[Path], list[str]]:
    def build(tmp: Path) -> list[str]:
        model = fixtures.cube_stl(tmp / "cube.stl")
        return ["slice", str(model), "--out", str(tmp / "out"), "--quiet", "--no-baselines",
                "--job", str(write_file(tmp / "job.toml", text))]
    return build


JOB_CASES = [
    Case("job", "smoothness_weight nan", _job("[slicing]\nsmoothness_weight = nan\n")),
    Case("job", "smoothness_weight inf", _job("[slicing]\nsmoothness_weight = inf\n")),
    Case("job", "layer_height_mm nan", _job("[slicing]\nlayer_height_mm = nan\n")),
    Case("job", "layer_height_mm 0.01 on a 20 mm cube (hours of work)",
         _job("[slicing]\nlayer_height_mm = 0.01\n")),
    Case("job", "layer_height_mm a string", _job("[slicing]\nlayer_height_mm = \"thin\"\n")),
    Case("job", "edge_length_mm 0.05 on a 20 mm cube (millions of tets)",
         _job("[mesh]\nedge_length_mm = 0.05\n")),
    Case("job", "max_iterations huge", _job("[slicing]\nmax_iterations = 1000000000\n")),
    Case("job", "deformation_iterations huge",
         _job("[toolpath]\ndeformation_iterations = 1000000000\n")),
    Case("job", "waypoint_spacing inf", _job("[toolpath]\nwaypoint_spacing = inf\n")),
    Case("job", "unknown key", _job("[slicing]\nlayer_hieght_mm = 0.6\n")),
    Case("job", "unknown section", _job("[slicer]\nlayer_height_mm = 0.6\n")),
    Case("job", "syntax error", _job("[slicing\nlayer_height_mm = \n")),
    Case("job", "section a number", _job("slicing = 3\n")),
    Case("job", "critical a number", _job("[slicing]\ncritical = [3]\n")),
    Case("job", "critical cone nan", _job("[slicing]\ncritical = [\"bottom:nan\"]\n")),
    Case("job", "profile names /etc/passwd", _job("[extrusion]\nprofile = \"/etc/passwd\"\n")),
    Case("job", "profile names a missing file", _job("[extrusion]\nprofile = \"../nope.toml\"\n")),
    Case("job", "max_size_mm nan", _job("[model]\nmax_size_mm = nan\n")),
    Case("job", "job file binary", lambda tmp: _slice(fixtures.cube_stl(tmp / "c.stl"), tmp,
                                                      "--job", str(write_file(tmp / "j.toml",
                                                                          b"\xff\xfe\x00")))),
    Case("job", "--layer-height nan flag",
         lambda tmp: _slice(fixtures.cube_stl(tmp / "c.stl"), tmp, "--layer-height", "nan")),
    Case("job", "--edge-length -1 flag",
         lambda tmp: _slice(fixtures.cube_stl(tmp / "c.stl"), tmp, "--edge-length", "-1")),
]


def _cell(text: str) -> Callable[[Path], list[str]]:
    def build(tmp: Path) -> list[str]:
        job = fixtures.job_dir(tmp / "job")
        return ["plan", str(job), "--no-figures", "--quiet", "--cell",
                str(write_file(tmp / "cell.toml", text))]
    return build


CELL_CASES = [
    Case("cell", "robot.base_xyz_mm nan", _cell("[robot]\nbase_xyz_mm = [nan, 0.0, 0.0]\n")),
    Case("cell", "tank.yaw_deg nan", _cell("[tank]\nyaw_deg = nan\n")),
    Case("cell", "planning.max_step_mm nan", _cell("[planning]\nmax_step_mm = nan\n")),
    Case("cell", "planning.max_step_mm 1e-6 (memory)", _cell("[planning]\nmax_step_mm = 1e-6\n")),
    Case("cell", "planning.spin_steps 1e8 (memory)", _cell("[planning]\nspin_steps = 100000000\n")),
    Case("cell", "planning.travel_speed_mm_s inf",
         _cell("[planning]\ntravel_speed_mm_s = inf\n")),
    Case("cell", "placement.search_step_mm 1e-9",
         _cell("[placement]\nsearch_step_mm = 1e-9\n")),
    Case("cell", "robot.base_xyz_mm two numbers", _cell("[robot]\nbase_xyz_mm = [1.0, 2.0]\n")),
    Case("cell", "robot.home_deg strings", _cell("[robot]\nhome_deg = [\"a\", \"b\"]\n")),
    Case("cell", "tool.tip_xyz_mm 1e300", _cell("[tool]\ntip_xyz_mm = [0.0, 0.0, 1e300]\n")),
    Case("cell", "tank.inner_size_mm inf", _cell("[tank]\ninner_size_mm = [inf, 500.0, 260.0]\n")),
    Case("cell", "unknown section", _cell("[robots]\nbase_xyz_mm = [0.0, 0.0, 0.0]\n")),
    Case("cell", "syntax error", _cell("[robot\n")),
]


def _toolpath(change: Callable[[dict[str, np.ndarray]], None]) -> Callable[[Path], list[str]]:
    def build(tmp: Path) -> list[str]:
        arrays = fixtures.toolpath_arrays()
        change(arrays)
        job = fixtures.job_dir(tmp / "job", arrays)
        return ["plan", str(job), "--no-figures", "--quiet"]
    return build


def _set(name: str, value: object, rows: slice = slice(None)) -> Callable[[dict], None]:
    def change(a: dict[str, np.ndarray]) -> None:
        a[name] = a[name].copy()
        a[name][rows] = value
    return change


def _empty(a: dict[str, np.ndarray]) -> None:
    for k in list(a):
        a[k] = a[k][:0]


def _scale_positions(a: dict[str, np.ndarray]) -> None:
    a["position"] = a["position"] * 1e6


def _inspect(change: Callable[[dict[str, np.ndarray]], None]) -> Callable[[Path], list[str]]:
    def build(tmp: Path) -> list[str]:
        arrays = fixtures.toolpath_arrays()
        change(arrays)
        job = fixtures.job_dir(tmp / "job", arrays)
        return ["inspect", str(job), "--no-figures", "--quiet", "--voxel", "0.5"]
    return build


STAGE_CASES = [
    Case("stage", "plan: empty toolpath.npz", _toolpath(_empty)),
    Case("stage", "plan: nan position", _toolpath(_set("position", np.nan, slice(3, 4)))),
    Case("stage", "plan: positions x1e6", _toolpath(_scale_positions)),
    Case("stage", "plan: zero speed", _toolpath(_set("speed", 0.0))),
    Case("stage", "plan: negative speed", _toolpath(_set("speed", -10.0))),
    Case("stage", "plan: deposits nothing", _toolpath(_set("extrude", False))),
    Case("stage", "plan: zero normals", _toolpath(_set("normal", 0.0))),
    Case("stage", "plan: negative width", _toolpath(_set("width", -1.0))),
    Case("stage", "plan: inf height", _toolpath(_set("height", np.inf, slice(0, 2)))),
    Case("stage", "plan: negative layer", _toolpath(_set("layer", -5))),
    Case("stage", "inspect: empty toolpath.npz", _inspect(_empty)),
    Case("stage", "inspect: nan position", _inspect(_set("position", np.nan, slice(3, 4)))),
    Case("stage", "inspect: positions x1e6", _inspect(_scale_positions)),
    Case("stage", "inspect: deposits nothing", _inspect(_set("extrude", False))),
    Case("stage", "inspect: zero speed", _inspect(_set("speed", 0.0))),
    Case("stage", "plan: toolpath.npz of garbage", lambda tmp: [
        "plan", str(write_file(tmp / "job" / "toolpath.npz", b"PK\x03\x04garbage").parent),
        "--no-figures", "--quiet"]),
    Case("stage", "plan: toolpath.npz missing an array", lambda tmp: [
        "plan", str(_drop(fixtures.job_dir(tmp / "job"), "speed")), "--no-figures", "--quiet"]),
    Case("stage", "inspect: garbage model.ply", lambda tmp: [
        "inspect", str(_garbage_model(fixtures.job_dir(tmp / "job"))), "--no-figures",
        "--quiet", "--voxel", "0.5"]),
    Case("stage", "inspect: --voxel nan", lambda tmp: [
        "inspect", str(fixtures.job_dir(tmp / "job")), "--voxel", "nan", "--quiet"]),
    Case("stage", "inspect: --filament nan", lambda tmp: [
        "inspect", str(fixtures.job_dir(tmp / "job")), "--filament", "nan", "--quiet"]),
]


def _drop(job: Path, name: str) -> Path:
    arrays = dict(np.load(job / "toolpath.npz"))
    del arrays[name]
    np.savez(job / "toolpath.npz", **arrays)
    return job


def _garbage_model(job: Path) -> Path:
    (job / "model.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 9\nend_header\n1 2\n")
    return job


def _gcode(text: str | bytes) -> Callable[[Path], list[str]]:
    def build(tmp: Path) -> list[str]:
        job = fixtures.job_dir(tmp / "job")
        return ["inspect", str(job), "--gcode", str(write_file(tmp / "a.gcode", text)),
                "--no-figures", "--quiet", "--voxel", "0.5"]
    return build


_G_OK = "G21\nG90\nM83\nG1 Z0.3 F600\nG1 X0 Y0\nG1 X4 Y0 E0.2\nG1 X4 Y4 E0.2\n"

GCODE_CASES = [
    Case("gcode", "move to 1e30 mm", _gcode(_G_OK + "G1 X1e30 Y0 E0.2\n")),
    Case("gcode", "extrusion 1e30", _gcode(_G_OK + "G1 X0 Y4 E1e30\n")),
    Case("gcode", "no extruding move", _gcode("G1 X1 Y1\nG1 X2 Y2\n")),
    Case("gcode", "empty file", _gcode("")),
    Case("gcode", "binary garbage", _gcode(bytes(range(256)) * 4)),
    Case("gcode", "arc of radius 1e12", _gcode(_G_OK + "G2 X4 Y4.1 I1e12 J0 E0.2\n")),
    Case("gcode", "layer 1e9 mm up", _gcode(_G_OK + "G1 Z1e9\nG1 X0 Y0 E0.2\n")),
]


ALL_CASES = (MESH_CASES + JOB_CASES + CELL_CASES + STAGE_CASES + GCODE_CASES + LAUNCH_CASES
             + SUBMIT_CASES)
