"""The lab's profiles: round trip, activation per cell, stale jobs, `mesp profile`."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from mesp_cell import profiles
from mesp_cell.calibration import fit_rate
from mesp_cell.cli import main
from mesp_cell.profile_write import calibrated_text, default_name
from slicer.extrusion import load_profile


@pytest.fixture()
def home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("MESP_HOME", str(tmp_path / "home"))
    return tmp_path / "home"


def _calibrated(name: str, C: float = 7.0) -> str:
    t = np.array([30.0, 60.0, 90.0])
    fit = fit_rate(t, C * t * 1.07e-3, 1.07, 6.57)
    when = datetime(2026, 11, 27, 9, 30).astimezone()
    return calibrated_text(profiles.find("ecoflex-0030"), name, when, rate=fit)


def test_a_calibrated_profile_round_trips(home: Path) -> None:
    base = profiles.find("ecoflex-0030")
    when = datetime(2026, 11, 27).astimezone()
    assert default_name(base, when) == "ecoflex-0030-2026-11-27"
    path = profiles.save(_calibrated("ecoflex-0030-2026-11-27"), "ecoflex-0030-2026-11-27")
    again = load_profile(path)
    assert again.calibrated and again.rate_mm3_s == pytest.approx(7.0)
    assert again.setpoint_mm3_s == 6.57 and again.beta == base.beta
    np.testing.assert_array_equal(again.speed, base.speed)
    assert path.read_text() == again.text and profiles.find(again.name).sha256 == again.sha256
    # a re-calibration of a dated profile is named by the new date, not stacked
    later = datetime(2027, 1, 2).astimezone()
    assert default_name(again, later) == "ecoflex-0030-2027-01-02"


def test_activation_is_per_cell_and_makes_old_jobs_stale(home: Path) -> None:
    old = profiles.active("sim")
    path = profiles.save(_calibrated("lab-a"), "lab-a")
    assert profiles.stale_reason(old, "sim") == ""
    profiles.activate("lab-a", "sim")
    assert profiles.active("sim").name == "lab-a" and profiles.active("cell").name == old.name
    why = profiles.stale_reason(old, "sim")
    assert "'ecoflex-0030'" in why and "'lab-a'" in why
    path.write_text(path.read_text().replace("rate_mm3_s = 7.0", "rate_mm3_s = 9.0"))
    assert profiles.active("sim").rate_mm3_s == pytest.approx(7.0)  # a copy is active
    other = home.parent / "elsewhere.toml"
    other.write_text(_calibrated("lab-b", 6.8))
    profiles.activate(str(other), "sim")  # by path: joins the library
    assert (home / "profiles" / "lab-b.toml").is_file()
    other.write_text(_calibrated("lab-b", 6.9))
    with pytest.raises(InputError, match="already has a different profile 'lab-b'"):
        profiles.activate(str(other), "sim")
    with pytest.raises(InputError, match="no profile 'nope'"):
        profiles.activate("nope", "sim")


def test_profile_cli(home: Path, capsys: pytest.CaptureFixture[str]) -> None:
    profiles.save(_calibrated("lab-a"), "lab-a")
    assert main(["profile", "--on", "sim", "list"]) == 0
    out = capsys.readouterr().out
    assert "cell 'sim' prints with ecoflex-0030" in out and "* ecoflex-0030" in out
    assert "  lab-a " in out
    assert main(["profile", "--on", "sim", "activate", "lab-a"]) == 0
    assert main(["profile", "--on", "sim", "show"]) == 0
    out = capsys.readouterr().out
    assert "lab-a: C 7 mm^3/s at set-point 6.57" in out and "(active on cell 'sim')" in out
    assert "calibrated extrusion 2026-11-27T09:30" in out
    assert main(["profile", "activate", "missing"]) == 2
    assert capsys.readouterr().err.startswith("mesp: error: no profile 'missing'")


def test_job_status_shows_the_jobs_and_the_cells_profile(home: Path, tmp_path: Path) -> None:
    from mesp_cell.commands.job import profile_line
    from mesp_cell.jobs import JobStore

    store = JobStore(home / "jobs.sqlite")
    (home / "import").mkdir(exist_ok=True)
    model = home / "import" / "part.stl"  # the store takes models from its import folder
    model.write_text("solid p\nendsolid p\n")
    job = store.submit(model, "sim")
    assert "not sliced yet; cell 'sim' prints with ecoflex-0030" in profile_line(job)
    profiles.active("sim").save_to_job(Path(job.dir))
    assert "(the cell's active profile)" in profile_line(job)
    profiles.save(_calibrated("lab-a"), "lab-a")
    profiles.activate("lab-a", "sim")
    assert "not the cell's active profile lab-a" in profile_line(job)
    store.close()
