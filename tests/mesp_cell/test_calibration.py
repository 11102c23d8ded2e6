"""Extrusion-rate calibration: the fit, the plausibility checks, the guided runs against the
emulated extruder's hidden truth (through a serial scale and the emulated noisy scale)."""

from __future__ import annotations

import io
import os
import threading
from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from mesp_cell.calibration import check_consistency, check_mass, fit_rate, run_extrusion
from mesp_cell.calibration_guide import Guide
from mesp_cell.cli import main
from mesp_cell.drivers.extruder_emulator import EmulatorThread
from mesp_cell.drivers.extruder_modbus import ModbusExtruder
from mesp_cell.drivers.extruder_plant import PlantParams
from mesp_cell.drivers.scale_emulator import EmulatedScale, ScaleNoise
from mesp_cell.scale import SerialScale

DENSITY = 1.07
SETPOINT = 6.0


class PtyScale:
    """A balance on a pty: answers ``W`` with ``grams[0]``."""

    def __init__(self, grams: list[float]) -> None:
        self.master, slave = os.openpty()
        self.path = os.ttyname(slave)
        self._slave = slave
        self.grams = grams
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        buf = b""
        while True:
            try:
                buf += os.read(self.master, 64)
            except OSError:
                return
            while b"\n" in buf:
                _, buf = buf.split(b"\n", 1)
                os.write(self.master, f"ST,GS   {self.grams[0]:10.5f} g\r\n".encode())

    def close(self) -> None:
        os.close(self.master)
        os.close(self._slave)


def test_rate_fit_is_exact_on_a_line_and_its_uncertainty_follows_the_scatter() -> None:
    t = np.array([30.0, 60.0, 90.0, 120.0])
    mass = (7.0 * t - 2.0) * DENSITY / 1000.0  # C = 7 mm^3/s, 2 mm^3 lost at start-up
    fit = fit_rate(t, mass, DENSITY, SETPOINT)
    assert fit.C == pytest.approx(7.0) and fit.v0 == pytest.approx(-2.0)
    assert fit.u_C == pytest.approx(0.0, abs=1e-9) and fit.setpoint == SETPOINT
    noisy = fit_rate(t, mass + np.array([1, -1, -1, 1]) * 1e-3, DENSITY, SETPOINT)
    # residuals +-1 mg over 2 degrees of freedom: s = 1.414 mg, Sxx = 4500 s^2
    assert noisy.u_C == pytest.approx(np.sqrt(4e-6 / 2 / 4500) / (DENSITY / 1000), rel=1e-6)
    assert noisy.expanded(0.95) == pytest.approx(4.303 * noisy.u_C, rel=1e-3)
    with pytest.raises(InputError, match=r"2 run\(s\) of 2 length\(s\) give no uncertainty"):
        fit_rate(t[:2], mass[:2], DENSITY, SETPOINT)
    with pytest.raises(InputError, match="no positive mass"):
        fit_rate(t, np.array([0.2, 0.0, 0.6, 0.8]), DENSITY, SETPOINT)


def test_implausible_masses_are_refused_with_the_reason() -> None:
    assert check_mass(0, 60.0, 0.42, 6.57, DENSITY, 0.3) == ""
    why = check_mass(1, 60.0, 42.0, 6.57, DENSITY, 0.3)  # typed in mg
    assert why.startswith("run 2: 42 g is outside the plausible") and "0.4218 g expected" in why
    assert "run 3" in check_mass(2, 60.0, 0.2, 6.57, DENSITY, 0.3)  # half a run
    t = [30.0, 60.0, 90.0, 120.0]
    good = [0.211, 0.422, 0.633, 0.844]
    assert check_consistency(t, good, 0.05) == ""
    spilled = [0.211, 0.35, 0.633, 0.844]
    assert check_consistency(t, spilled, 0.05).startswith("run 2 (60 s, 0.35 g) disagrees")


def test_a_typed_implausible_mass_is_asked_again() -> None:
    out = io.StringIO()
    answers = iter(["", "422", "zero", "0.425"])  # Enter for the cup, mg, not a number, g

    def check(i: int, t: float, g: float) -> str:
        return check_mass(i, t, g, 6.57, DENSITY, 0.3)

    guide = Guide(1, 6.57, check, lambda i, t: 0.42, ask=lambda _: next(answers), out=out,
                  countdown_s=0)
    guide.before_run(0, 60.0)
    assert guide.weigh(0, 60.0) == 0.425
    text = out.getvalue()
    assert "refused: run 1: 422 g is outside" in text and "'zero' is not a number" in text
    with pytest.raises(InputError, match="needs the masses from a scale"):
        Guide(1, 6.57, check, lambda i, t: 0.42, yes=True)


def _calibrate(gain: float, seed: int, scale_noise: ScaleNoise | None = None) -> float:
    """One scripted calibration on the emulator at 40x; the fitted C."""
    params = PlantParams(gain=gain, time_scale=40.0, startup_tau_s=0.5)
    with EmulatorThread(params) as emu:
        scale = EmulatedScale(emu.plant, DENSITY, scale_noise, seed=seed)
        guide = Guide(4, SETPOINT, lambda i, t, g: "", lambda i, t: 0.0, scale, yes=True,
                      out=io.StringIO())
        seconds = [30.0, 60.0, 90.0, 120.0]
        masses = run_extrusion(ModbusExtruder("127.0.0.1", emu.port), SETPOINT, seconds,
                               guide.before_run, guide.during_run, guide.weigh, 2.0, 40.0)
    return fit_rate(seconds, masses, DENSITY, SETPOINT).C


@pytest.mark.slow
@pytest.mark.timeout(180)
def test_calibration_recovers_the_hidden_rate_within_1_percent_over_5_runs() -> None:
    gain = 1.13
    errors = np.array([_calibrate(gain, seed) / (gain * SETPOINT) - 1 for seed in range(5)])
    print("recovery errors:", np.round(errors * 100, 3), "%")
    assert np.all(np.abs(errors) < 0.01), errors


@pytest.mark.timeout(60)
def test_masses_read_from_a_serial_scale() -> None:
    gain = 0.9
    with EmulatorThread(PlantParams(gain=gain, time_scale=40.0)) as emu:
        reading = [3.0]
        dev = PtyScale(reading)
        scale = SerialScale(dev.path)
        mark = [emu.plant.true_volume]

        def before(i: int, t: float) -> None:  # a fresh cup: the scale shows its 3 g
            reading[0] = 3.0
            mark[0] = emu.plant.true_volume
            guide.before_run(i, t)

        def weigh(i: int, t: float) -> float:
            reading[0] = 3.0 + (emu.plant.true_volume - mark[0]) * DENSITY / 1000.0
            return guide.weigh(i, t)

        guide = Guide(3, SETPOINT, lambda i, t, g: "", lambda i, t: 0.0, scale, yes=True,
                      out=io.StringIO())
        seconds = [20.0, 40.0, 60.0]
        masses = run_extrusion(ModbusExtruder("127.0.0.1", emu.port), SETPOINT, seconds,
                               before, guide.during_run, weigh, 2.0, 40.0)
        scale.close()
        dev.close()
    assert fit_rate(seconds, masses, DENSITY, SETPOINT).C == pytest.approx(gain * SETPOINT,
                                                                           rel=0.01)


def test_cli_fits_a_masses_file_and_refuses_an_implausible_one(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    from mesp_cell import profiles

    monkeypatch.setenv("MESP_HOME", str(tmp_path / "home"))
    runs = tmp_path / "runs.csv"
    runs.write_text("seconds,mass_g\n30,0.2250\n60,0.4520\n90,0.6790\n120,0.9060\n")
    assert main(["calibrate", "extrusion", "--masses", str(runs), "--name", "bath-1"]) == 0
    out = capsys.readouterr().out
    assert "C = 7.07" in out and "mesp profile activate bath-1" in out
    made = profiles.find("bath-1")
    assert made.calibrated and made.rate_mm3_s == pytest.approx(0.227 / 30 / DENSITY * 1000,
                                                                rel=1e-3)
    assert (tmp_path / "home" / "profiles" / "bath-1-extrusion.png").stat().st_size > 10_000
    assert profiles.active("sim").name == "ecoflex-0030"  # not activated
    # the same name again is refused, not overwritten
    assert main(["calibrate", "extrusion", "--masses", str(runs), "--name", "bath-1"]) == 2
    assert "bath-1.toml exists" in capsys.readouterr().err
    runs.write_text("seconds,mass_g\n30,0.2250\n60,4.520\n90,0.6790\n")  # 4.520: a slip
    assert main(["calibrate", "extrusion", "--masses", str(runs)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("mesp: error: run 2: 4.52 g is outside the plausible") and (
        "\n" not in err)
    runs.write_text("seconds,mass_g\n30,0.2250\n60,0.4000\n90,0.6790\n120,0.9060\n")
    assert main(["calibrate", "extrusion", "--masses", str(runs)]) == 2
    assert "run 2 (60 s, 0.4 g) disagrees with the other runs" in capsys.readouterr().err
    # too few runs is refused before the extruder moves (no extruder is even needed)
    assert main(["calibrate", "extrusion", "--emulate", "1.0", "--yes", "--seconds", "30"]) == 2
    assert "1 run(s) of 1 length(s)" in capsys.readouterr().err
