"""Recalibrate the emulated extruder at another true rate, then print on the twin.

The whole cell runs (real processes, the real slicer and planner on a ``CUBE_MM`` cube with the
cube example's job file, the emulated Modbus extruder whose true rate is ``GAIN`` x its
set-point). After `mesp calibrate
extrusion --activate`, a job sliced with the old profile is refused before it is planned or
moves, and a job sliced with the new profile gives the part the toolpath's volume within 1 %,
by the emulator's hidden truth (not by the totaliser, which believes the set-point). The part's
ink is the truth less the ink the cell extruded with the nozzle at rest (the prime and the
leads, ``ink_at_rest`` in the job's report): on a fast twin the wall-clock wait before the
robot takes a stream counts ``time_scale`` times over there, 5-38 mm^3 (0.2-1.4 %) at 40x.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pytest

from core.errors import InputError
from mesp_cell.cli import main
from tests.mesp_cell import synthetic

ROOT = Path(__file__).resolve().parents[2]
GAIN = 1.08  # the emulated extruder delivers 8 % more than it is asked
TIME_SCALE = 40.0
#: mm, the cube's edge: the example's 20 mm cube prints for 21 simulated minutes; this one
#: has about as many paths (starts and stops, where a rate error shows) in a third of the volume
CUBE_MM = 14.0


def _truth(home: Path) -> float:
    """The emulator's hidden delivered volume now, mm^3: the first of its --truth files
    (written every 0.2 s) written after this call."""
    path = home / "run" / "sim.extruder-truth.json"
    now = time.time()
    end = time.monotonic() + 30.0
    while time.monotonic() < end:
        if path.is_file() and path.stat().st_mtime > now:
            return float(json.loads(path.read_text())["true_volume_mm3"])
        time.sleep(0.05)
    raise AssertionError(f"the extruder emulator wrote no {path.name} for 30 s")


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_recalibrated_cell_refuses_a_stale_job_and_prints_the_toolpath_volume(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    from mesp_cell import profiles
    from mesp_cell.launcher import start_cell
    from slicer.profiles import FACTORY

    home = tmp_path / "home"
    monkeypatch.setenv("MESP_HOME", str(home))
    old = profiles.active("sim")
    assert old.name == FACTORY
    assert main(["calibrate", "extrusion", "--emulate", str(GAIN), "--yes", "--time-scale",
                 str(TIME_SCALE), "--seed", "7", "--name", "lab-2026", "--activate",
                 "--on", "sim"]) == 0
    new = profiles.active("sim")
    true_rate = GAIN * new.setpoint_mm3_s
    print(f"calibrated C {new.rate_mm3_s:.4f} mm^3/s, true {true_rate:.4f}: "
          f"{new.rate_mm3_s / true_rate - 1:+.3%}")
    assert new.name == "lab-2026" and new.calibrated
    assert new.rate_mm3_s == pytest.approx(true_rate, rel=0.01)
    # the cube example's job, without the width baselines (a third of the toolpath's work,
    # measured for the report only: nothing printed depends on them)
    job = ((ROOT / "examples" / "cube.toml").read_text()
           + "\n[toolpath]\nmeasure_baselines = false\n")
    fresh_job = tmp_path / "fresh.toml"
    fresh_job.write_text(job)
    stale_job = tmp_path / "stale.toml"
    stale_job.write_text(job + f'\n[extrusion]\nprofile = "{FACTORY}"\n')
    cube = synthetic.write_cube(tmp_path / "cube.stl", CUBE_MM)
    with start_cell(overrides={"time_scale": TIME_SCALE, "true_gain": GAIN,
                               "prime_s": 0.5}) as cell:
        client = cell.client()
        try:
            stale = client.submit(cube, stale_job)
            fresh = client.submit(cube, fresh_job)
            refused = client.wait(stale.id, timeout=240)
            before = _truth(home)
            try:
                client.confirm_ready(fresh.id, timeout=240)  # the operator confirms the tank
            except InputError as exc:  # the job ended before it asked: say why it did
                raise AssertionError(f"{exc}: {client.status(fresh.id).reason}") from exc
            done = client.wait(fresh.id, timeout=400)
            for _ in range(3):  # a loaded 2-core host may trip an interlock: resume, as a user
                if done.state != "interrupted":
                    break
                print(f"resumed after: {done.reason}")
                client.resume(fresh.id)
                done = client.wait(fresh.id, timeout=400)
            after = _truth(home)
        finally:
            client.close()
    assert refused.state == "failed" and refused.layers == 0, refused  # never planned, moved
    assert f"'{FACTORY}'" in refused.reason and "lab-2026" in refused.reason
    assert done.state == "done", done.reason
    report = json.loads((Path(done.dir) / "report.json").read_text())
    assert report["toolpath"]["profile"]["sha256"] == new.sha256
    assert report["print"]["profile"]["name"] == "lab-2026"
    toolpath = float(report["toolpath"]["deposited_volume_mm3"])
    rest = float(report["ink_at_rest"]["mm3"])
    delivered = after - before - rest
    reported = float(report["print"]["part_volume_mm3"])
    print(f"toolpath {toolpath:.1f} mm^3; for the part: delivered {delivered:.1f} mm^3 "
          f"({delivered / toolpath - 1:+.3%}), reported {reported:.1f} mm^3 "
          f"({reported / toolpath - 1:+.3%}); at rest {rest:.1f} mm^3")
    assert 0.0 < rest < 0.05 * toolpath
    assert delivered == pytest.approx(toolpath, rel=0.01)
    assert reported == pytest.approx(toolpath, rel=0.01)
    switch = float(report["print"]["switch_latency_mm3"])
    assert done.volume == pytest.approx(reported + rest + switch, rel=1e-6)
    assert os.environ["MESP_HOME"] == str(home)
