"""A fast simulated print: many short paths and travel moves at a high time scale.

The whole cell runs (real processes, the emulated Modbus extruder on the twin's scaled clock)
with a synthetic job (``slice_job``/``plan_job`` below, named by the launch overrides) whose
travel moves between paths are far shorter than the old wall-clock lead and margin spanned at
10x. (At 40x the switches' wall-clock latency on this loaded 2-core host, 2-40 ms each, is
0.1-1.6 s of simulated flow per switch, more noise than the measured latency takes off.) The
job must print completely, every waypoint once, and the part's ink (less the ink at rest and
what the measured switch latency moved) must be the toolpath's within the print check's 2 %.
"""

from __future__ import annotations

import json
import os
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.artifacts import save_npz
from core.stages import Toolpath
from mesp_cell.nodes.print_check import VOLUME_TOLERANCE
from slicer.extrusion import ACTIVE, load_profile
from tests.mesp_cell import synthetic

pytestmark = pytest.mark.slow  # the demo end to end

HOME = np.radians([0.0, -100.0, 100.0, -90.0, -90.0, 0.0])
PATHS = 40          # deposition paths
PER_PATH = 8        # waypoints per path
PATHS_PER_LAYER = 4
STEP = 10           # trajectory samples per waypoint (0.1 s)
RATE_HZ = 100.0     # trajectory sample rate
TRAVEL = 25         # samples (0.25 s) of travel between paths
TIME_SCALE = 10.0    # each switch's wall-clock latency counts 10 times over in simulated time
RATE = load_profile(ACTIVE).setpoint_mm3_s  # mm^3/s, a fresh cell's set-point (factory profile)
WIDTH = RATE * PER_PATH * STEP / RATE_HZ / ((PER_PATH - 1) * 1.0 * 0.6)  # mm, see toolpath()


def toolpath() -> Toolpath:
    """PATHS short straight paths of PER_PATH waypoints 1 mm apart, PATHS_PER_LAYER per layer;
    the width makes the toolpath's volume the ink the trajectory deposits at RATE (PER_PATH x
    STEP / RATE_HZ s per path over PER_PATH - 1 mm), as a real plan's is."""
    n = PATHS * PER_PATH
    path = np.repeat(np.arange(PATHS), PER_PATH).astype(np.int32)
    layer = (path // PATHS_PER_LAYER).astype(np.int32)
    along = np.tile(np.arange(PER_PATH, dtype=np.float64), PATHS)
    pos = np.stack([along, 2.0 * (path % PATHS_PER_LAYER), 0.6 * layer], axis=1)
    normal = np.tile([0.0, 0.0, 1.0], (n, 1))
    return Toolpath(position=pos, normal=normal, layer=layer, path=path,
                    height=np.full(n, 0.6), width=np.full(n, WIDTH), speed=np.full(n, 9.0),
                    extrude=np.ones(n, bool), pattern=np.zeros(n, np.int8))


def trajectory_arrays() -> dict[str, np.ndarray]:
    """A smooth joint motion around HOME through every waypoint, with a travel move of TRAVEL
    samples (no deposition) between consecutive paths."""
    rows_wp: list[int] = []
    rows_ex: list[bool] = []
    for p in range(PATHS):
        for i in range(PER_PATH):
            rows_wp += [p * PER_PATH + i] + [-1] * (STEP - 1)
            rows_ex += [True] * STEP
        rows_wp += [-1] * TRAVEL
        rows_ex += [False] * TRAVEL
    wp = np.asarray(rows_wp, dtype=np.int32)
    M = wp.shape[0]
    t = np.arange(M) / RATE_HZ
    s = np.sin(2 * np.pi * t / t[-1])[:, None]
    q = HOME + 0.15 * s * np.array([1.0, 0.5, -0.5, 0.3, 0.2, 0.1])
    qd = np.gradient(q, t, axis=0)
    return {"t": t, "q": q, "qd": qd, "tcp": np.zeros((M, 3)), "waypoint": wp,
            "alpha": np.full(M, 90.0), "extrude": np.asarray(rows_ex, bool),
            "base_T": np.eye(4), "tool_T": np.eye(4), "model_T": np.eye(4)}


def deposition_s() -> float:
    """Simulated seconds of deposition in the trajectory."""
    return PATHS * PER_PATH * STEP / RATE_HZ


def slice_job(model: Path, job_file: Path | None, out_dir: Path, cell: str,
              cell_file: Path | None = None) -> dict[str, Any]:
    """Stands in for the slicing pipeline (launch override ``slice_fn``)."""
    from mesp_cell.profiles import active

    toolpath().save(Path(out_dir))
    active(cell).save_to_job(Path(out_dir))  # the cell's calibration, as the real slicer
    return {}


def plan_job(job_dir: Path, cell_file: Path | None) -> dict[str, Any]:
    """Stands in for the planner (launch override ``plan_fn``)."""
    save_npz(Path(job_dir) / "trajectory.npz", trajectory_arrays())
    return {}


def test_trajectory_has_short_travel_moves() -> None:
    a = trajectory_arrays()
    ex = a["extrude"]
    starts = np.flatnonzero(ex[1:] & ~ex[:-1]) + 1
    assert starts.size == PATHS - 1
    # Every travel move is far shorter than the wall-clock lead (0.3 s) and switch margin
    # (0.1 s) used to span at 10x (3 s and 1 s of simulated time).
    assert TRAVEL / RATE_HZ < 0.1 * TIME_SCALE


@pytest.mark.timeout(120)
def test_short_paths_print_completely_at_high_time_scale(tmp_path: Path) -> None:
    from mesp_cell.launcher import start_cell
    from mesp_cell.messages import ExtruderState, WaypointReached

    old = os.environ.get("MESP_HOME")
    os.environ["MESP_HOME"] = str(tmp_path / "home")
    model = tmp_path / "part.stl"
    synthetic.write_cube(model)  # a real model: submit loads it
    lock = threading.Lock()
    waypoints: list[int] = []
    states: list[ExtruderState] = []
    try:
        with start_cell(overrides={"time_scale": TIME_SCALE,
                                   "slice_fn": "tests.mesp_cell.test_demo:slice_job",
                                   "plan_fn": "tests.mesp_cell.test_demo:plan_job",
                                   "prime_s": 0.5}) as cell:
            client = cell.client()
            try:
                bus = client.bus()

                def on_wp(m: WaypointReached) -> None:
                    with lock:
                        waypoints.append(m.waypoint)

                def on_ext(m: ExtruderState) -> None:
                    with lock:
                        states.append(m)

                bus.subscribe("robot", "waypoint", WaypointReached, on_wp)
                bus.subscribe("extruder", "state", ExtruderState, on_ext)
                job = client.submit(model)
                client.confirm_ready(job.id)
                done = client.wait(job.id, timeout=90)
                # waypoint events and the extruder's stopped state may trail the job's end
                # (by more than a second on a loaded host)
                end = time.monotonic() + 10.0
                while time.monotonic() < end and (len(waypoints) < PATHS * PER_PATH or
                                                  not states or states[-1].running):
                    time.sleep(0.01)
            finally:
                client.close()
    finally:
        if old is None:
            os.environ.pop("MESP_HOME", None)
        else:
            os.environ["MESP_HOME"] = old
    assert done.state == "done", done.reason
    with lock:
        printed = list(waypoints)
        seen = list(states)
    all_wp = list(range(PATHS * PER_PATH))
    assert printed == all_wp, ("a waypoint was skipped or repeated", len(printed),
                               sorted(set(all_wp) - set(printed)))
    assert done.percent == 100.0
    assert seen and not seen[-1].running and not seen[-1].fault, seen[-1:]
    # The emulated extruder runs on the twin's clock: its totaliser holds the deposition time
    # of the trajectory (simulated seconds) plus the 0.5 s prime and the lead at rest. "done"
    # means the part's ink (less the ink at rest) is the toolpath's within 2 %. The switches'
    # wall-clock latency moves no ink: the robot holds the shared clock at each switch until
    # the extruder took it, so the latency it measures on that clock (in the report) is 0.
    report = json.loads((Path(done.dir) / "report.json").read_text())["print"]
    print(f"extruded {done.volume:.1f} mm^3; for the part {report['part_volume_mm3']:.1f} of "
          f"{report['toolpath_volume_mm3']:.1f} mm^3 ({100 * report['volume_error']:+.2f} %), "
          f"switch latency at {TIME_SCALE:g}x {report['switch_latency_mm3']:+.1f} mm^3")
    assert abs(report["volume_error"]) <= VOLUME_TOLERANCE
    assert report["toolpath_volume_mm3"] == pytest.approx(RATE * deposition_s())
    assert report["switch_latency_mm3"] == 0.0  # each switch landed at its simulated time
    assert done.volume > RATE * (deposition_s() + 0.5) * (1 - VOLUME_TOLERANCE)


def test_demo_summary_compares_extruded_volume_and_pace(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    import json

    from mesp_cell.commands.demo import _against_toolpath, _Printer, _summary

    (tmp_path / "report.json").write_text(json.dumps({
        "toolpath": {"deposited_volume_mm3": 1000.0, "waypoints": 10, "length_mm": 100.0,
                     "volume_error": 0.001},
        "plan": {"duration_s": 800.0},
        "inspect": {"infill_ratio": 0.98, "interior_infill_ratio": 0.995, "pore_ratio": 0.001,
                    "surface_error_mm": {"mean": 0.2},
                    "as_planned": {"slowed_length_fraction": 0.02, "extra_ink_mm3": 12.0,
                                   "surface_error_mm": {"mean": 0.21}}}}))
    assert _against_toolpath(tmp_path, 1010.0) == " (+1.0% of the toolpath's 1000)"
    assert "warning" not in capsys.readouterr().err
    assert _against_toolpath(tmp_path, 2900.0) == " (+190.0% of the toolpath's 1000)"
    assert "warning: the extruder delivered +190.0%" in capsys.readouterr().err
    _summary(tmp_path, printing_s=20.0, time_scale=80.0)
    out = capsys.readouterr().out
    assert "800 s of printing, printed in 20 s on the twin: 40x (asked 80x)" in out
    assert "2.0% of the path slowed, 12 mm^3 more ink, surface error mean 0.210 mm" in out

    class Job:
        layer, layers, percent, eta_s, volume = 0, 3, 0.0, 0.0, 0.0
        state = "sliced"

    import mesp_cell.commands.demo as demo

    clock = iter([10.0, 11.0, 15.0, 19.5])  # the monotonic time of each progress
    monkeypatch.setattr(demo.time, "monotonic", lambda: next(clock))
    printer = _Printer()
    for state in ("sliced", "printing", "printing", "done"):
        Job.state = state
        printer.progress(Job())
    assert printer.printing_s() == 8.5  # from the first printing state to done
