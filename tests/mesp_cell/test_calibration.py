"""Calibration end to end against the emulated extruder's hidden truth, and the morphology fit."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import numpy as np
import pytest

from mesp_cell.calibration import (
    SerialScale,
    base_profile,
    fit_morphology,
    fit_rate,
    read_morphology_csv,
    run_extrusion,
    write_profile,
)
from mesp_cell.cli import main
from mesp_cell.drivers.extruder_emulator import EmulatorThread
from mesp_cell.drivers.extruder_modbus import ModbusExtruder
from mesp_cell.drivers.extruder_plant import PlantParams
from slicer.errors import InputError
from slicer.extrusion import load_profile

DENSITY = 1.07


class PtyScale:
    """A balance on a pty: answers ``W`` with the emulator's hidden delivered mass."""

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


def test_rate_fit_is_exact_on_a_line() -> None:
    s = np.array([2.0, 4.0, 8.0])
    true_rate = 1.1 * s + 0.3
    nominal = s * 10.0  # 10 s runs
    mass = true_rate * 10.0 * DENSITY / 1000.0
    fit = fit_rate(s, nominal, mass, 10.0, DENSITY, operating_setpoint=6.57)
    assert fit.slope == pytest.approx(1.1) and fit.intercept == pytest.approx(0.3)
    assert fit.r2 == pytest.approx(1.0) and fit.C == pytest.approx(1.1 * 6.57 + 0.3)
    assert fit.setpoint_for(fit.C) == pytest.approx(6.57)
    with pytest.raises(InputError):
        fit_rate(s, nominal, np.array([1.0, 0.0, 1.0]), 10.0, DENSITY)


def test_extrusion_calibration_recovers_the_hidden_rate_through_a_serial_scale(
        tmp_path: Path) -> None:
    gain = 1.2
    with EmulatorThread(PlantParams(tau_s=0.05, gain=gain)) as emu:
        reading = [0.0]
        scale_dev = PtyScale(reading)
        scale = SerialScale(scale_dev.path)
        mark = [emu.plant.true_volume]

        def weigh(i: int, sp: float) -> float:
            # The cup is emptied after each weighing: the scale shows this run's output.
            reading[0] = (emu.plant.true_volume - mark[0]) * DENSITY / 1000.0
            mark[0] = emu.plant.true_volume
            return scale.grams()

        # ~20 and ~50 mg per run on a 10 ug balance: quantisation below 0.1 %.
        fit = run_extrusion(ModbusExtruder("127.0.0.1", emu.port), [15.0, 40.0], 1.0, weigh,
                            DENSITY, operating_setpoint=6.57, settle_s=0.4)
        scale.close()
        scale_dev.close()
    assert fit.slope == pytest.approx(gain, rel=0.02)
    assert abs(fit.intercept) < 0.3
    assert fit.C == pytest.approx(gain * 6.57, rel=0.02)
    out = write_profile(base_profile("ecoflex-0030"), tmp_path / "cal.toml", rate=fit)
    profile = load_profile(out)
    assert profile.rate_mm3_s == pytest.approx(fit.C, abs=1e-3)
    assert base_profile(out)["calibration"]["extrusion"]["slope"] == pytest.approx(fit.slope)


def test_morphology_fit_recovers_power_laws_and_writes_a_valid_profile(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    v = np.repeat([1.0, 2.0, 4.0, 8.0, 16.0], 3)
    w = 3.0 * v**-0.55 * np.exp(rng.normal(0, 0.01, v.size))
    h = 2.0 * v**-0.45 * np.exp(rng.normal(0, 0.01, v.size))
    table = tmp_path / "m.csv"
    table.write_text("# measured in the bath\nspeed_mm_s,width_mm,height_mm\n" + "".join(
        f"{a},{b},{c}\n" for a, b, c in zip(v, w, h, strict=True)))
    fit = fit_morphology(*read_morphology_csv(table))
    assert fit.b_w == pytest.approx(-0.55, abs=0.02) and fit.b_h == pytest.approx(-0.45, abs=0.02)
    assert fit.a_h == pytest.approx(2.0, rel=0.03) and fit.r2_h > 0.99
    assert np.all(np.diff(fit.height) < 0) and fit.speed[0] == 1.0 and fit.speed[-1] == 16.0
    out = tmp_path / "p.toml"
    assert main(["calibrate", "morphology", str(table), "--out", str(out)]) == 0
    profile = load_profile(out)
    assert profile.calibrated
    # f inverts the fitted h_f: the speed for h_f(4 mm/s) is 4 mm/s.
    assert profile.speed_for_height(2.0 * 4.0**-0.45) == pytest.approx(4.0, rel=0.03)


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
