"""Filament morphology calibration: power-law fit, table, profile and plot."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from mesp_cell.cli import main
from mesp_cell.morphology_fit import fit_morphology, read_morphology_csv


def _table(path: Path) -> Path:
    rng = np.random.default_rng(0)
    v = np.repeat([1.0, 2.0, 4.0, 8.0, 16.0], 3)
    w = 3.0 * v**-0.55 * np.exp(rng.normal(0, 0.01, v.size))
    h = 2.0 * v**-0.45 * np.exp(rng.normal(0, 0.01, v.size))
    path.write_text("# measured in the bath\nspeed_mm_s,width_mm,height_mm\n" + "".join(
        f"{a},{b},{c}\n" for a, b, c in zip(v, w, h, strict=True)))
    return path


def test_morphology_fit_recovers_power_laws(tmp_path: Path) -> None:
    fit = fit_morphology(*read_morphology_csv(_table(tmp_path / "m.csv")))
    assert fit.b_w == pytest.approx(-0.55, abs=0.02) and fit.b_h == pytest.approx(-0.45, abs=0.02)
    assert fit.a_h == pytest.approx(2.0, rel=0.03) and fit.r2_h > 0.99
    assert np.all(np.diff(fit.height) < 0) and fit.speed[0] == 1.0 and fit.speed[-1] == 16.0


def test_cli_writes_a_new_activated_profile_and_a_plot(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from mesp_cell import profiles

    monkeypatch.setenv("MESP_HOME", str(tmp_path / "home"))
    table = _table(tmp_path / "m.csv")
    assert main(["calibrate", "morphology", str(table), "--name", "bath-f", "--activate",
                 "--on", "cell"]) == 0
    profile = profiles.active("cell")
    assert profile.name == "bath-f" and profiles.active("sim").name == "ecoflex-0030"
    # f inverts the fitted h_f: the speed for h_f(4 mm/s) is 4 mm/s.
    assert profile.speed_for_height(2.0 * 4.0**-0.45) == pytest.approx(4.0, rel=0.03)
    assert profile.rate_mm3_s == profiles.find("ecoflex-0030").rate_mm3_s  # C kept
    plot = tmp_path / "home" / "profiles" / "bath-f-morphology.png"
    assert plot.stat().st_size > 10_000


def test_bad_morphology_tables_are_refused(tmp_path: Path) -> None:
    table = tmp_path / "m.csv"
    table.write_text("speed_mm_s,width_mm,height_mm\n1,2,1\n2,1.5,1.2\n")
    with pytest.raises(InputError, match="height does not fall"):
        fit_morphology(*read_morphology_csv(table))
    table.write_text("speed,width\n1,2\n")
    with pytest.raises(InputError, match="no column height_mm"):
        read_morphology_csv(table)
    table.write_text("speed,width,height\n1,2,x\n")
    with pytest.raises(InputError, match="non-number"):
        read_morphology_csv(table)
    assert main(["calibrate", "morphology", str(tmp_path / "none.csv")]) == 2
