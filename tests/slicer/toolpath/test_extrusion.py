"""Extrusion profile: eq. 4, the monotone fit of f, validation of bad profiles."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from slicer.extrusion import (
    ACTIVE,
    PROFILE_FILE,
    ExtrusionProfile,
    load_job_profile,
    load_profile,
    profile_from_dict,
)


@pytest.fixture(scope="module")
def eco() -> ExtrusionProfile:
    return load_profile("ecoflex-0030")


def test_bundled_profile_constants(eco: ExtrusionProfile) -> None:
    assert eco.rate_mm3_s == 6.57
    assert eco.beta == 0.5
    assert not eco.calibrated and "paper" in eco.provenance
    lo, hi = eco.layer_height_range
    assert lo <= 0.3 and hi >= 1.5  # the table covers layer heights 0.3 .. 1.5 mm


def test_table_is_volume_consistent_and_oval_to_round(eco: ExtrusionProfile) -> None:
    assert eco.area_consistency() < 0.005  # pi/4 w h v = C
    ratio = eco.filament_width / eco.filament_height
    assert ratio[0] == pytest.approx(1.6, abs=0.1)
    assert ratio[-1] == pytest.approx(1.0, abs=0.02)
    assert np.all(np.diff(ratio) <= 0)


def test_fit_reproduces_table_and_is_monotone(eco: ExtrusionProfile) -> None:
    assert np.allclose(eco.speed_for_height(eco.filament_height), eco.speed, rtol=1e-9)
    w, h = eco.filament_size(eco.speed)
    assert np.allclose(w, eco.filament_width, rtol=1e-9)
    assert np.allclose(h, eco.filament_height, rtol=1e-9)
    hh = np.linspace(*eco.height_range, 2001)
    v = eco.speed_for_height(hh)
    assert np.all(np.diff(v) < 0)
    # f inverts h_f(v)
    assert np.allclose(eco.filament_size(v)[1], hh, rtol=2e-3)  # two PCHIPs, not exact


def test_width_is_eq4(eco: ExtrusionProfile) -> None:
    H = np.array([0.3, 0.45, 0.6, 0.9, 1.2, 1.5])
    v = eco.speed_at(H)
    assert np.allclose(v, eco.speed_for_height(H / 0.5))
    assert np.allclose(eco.width(H), 6.57 / (H * v))
    # with H = beta h_f and A = C / v: W = 2 A / h_f = (pi / 2) w_f, wider than the filament
    w_f, _ = eco.filament_size(v)
    assert np.allclose(eco.width(H), 0.5 * np.pi * w_f, rtol=0.01)


def test_clamped_outside_table(eco: ExtrusionProfile) -> None:
    assert eco.speed_for_height(100.0) == pytest.approx(eco.speed[0])
    assert eco.speed_for_height(0.01) == pytest.approx(eco.speed[-1])
    assert not eco.in_range(5.0) and eco.in_range(0.6)
    with pytest.raises(InputError):
        eco.width(np.array([0.5, 0.0]))


def _data(**changes: object) -> dict:
    data: dict = {
        "name": "t", "rate_mm3_s": 6.57, "setpoint_mm3_s": 6.0, "beta": 0.5,
        "morphology": {"speed_mm_s": [1.0, 2.0, 4.0], "filament_width_mm": [3.0, 2.0, 1.0],
                       "filament_height_mm": [2.0, 1.5, 1.0]},
    }
    for key, value in changes.items():
        if key in data["morphology"]:
            data["morphology"][key] = value
        else:
            data[key] = value
    return data


@pytest.mark.parametrize("changes", [
    {"rate_mm3_s": -1.0},
    {"setpoint_mm3_s": 0.0},
    {"beta": 1.5},
    {"speed_mm_s": [1.0, 1.0, 4.0]},
    {"filament_height_mm": [2.0, 2.5, 1.0]},
    {"filament_width_mm": [3.0, 4.0, 1.0]},
    {"filament_width_mm": [3.0, 2.0]},
    {"filament_height_mm": [2.0, -1.5, -3.0]},
])
def test_bad_profiles_raise(changes: dict) -> None:
    with pytest.raises(InputError):
        profile_from_dict(_data(**changes))


def test_good_custom_profile_and_missing_key() -> None:
    prof = profile_from_dict(_data())
    assert prof.speed_for_height(1.5) == pytest.approx(2.0)
    bad = _data()
    del bad["beta"]
    with pytest.raises(InputError, match="beta"):
        profile_from_dict(bad)


def test_load_by_path_and_errors(tmp_path: Path) -> None:
    path = tmp_path / "p.toml"
    path.write_text(
        'rate_mm3_s = 5.0\nsetpoint_mm3_s = 4.5\nbeta = 0.6\n'
        '[morphology]\nspeed_mm_s = [1.0, 3.0]\n'
        'filament_width_mm = [2.0, 1.0]\nfilament_height_mm = [1.5, 0.9]\n'
    )
    prof = load_profile(path)
    assert prof.rate_mm3_s == 5.0 and prof.beta == 0.6 and prof.setpoint_mm3_s == 4.5
    with pytest.raises(InputError, match="unknown extrusion profile"):
        load_profile("no-such-material")
    with pytest.raises(InputError):
        load_profile(tmp_path / "missing.toml")
    broken = tmp_path / "b.toml"
    broken.write_text("rate_mm3_s = [")
    with pytest.raises(InputError, match="TOML"):
        load_profile(broken)


def test_a_job_records_its_profile_verbatim(tmp_path: Path) -> None:
    eco = load_profile("ecoflex-0030")
    assert load_profile(ACTIVE).sha256 == eco.sha256  # no cell: the factory profile
    eco.save_to_job(tmp_path)
    assert (tmp_path / PROFILE_FILE).read_text() == eco.text
    again = load_job_profile(tmp_path)
    assert again.sha256 == eco.sha256 and again.rate_mm3_s == eco.rate_mm3_s
    edited = tmp_path / "edited"
    edited.mkdir()
    (edited / PROFILE_FILE).write_text(eco.text.replace("setpoint_mm3_s = 6.57",
                                                        "setpoint_mm3_s = 6.0"))
    assert load_job_profile(edited).sha256 != eco.sha256  # any change is another calibration
    with pytest.raises(InputError, match="records no extrusion profile"):
        load_job_profile(tmp_path / "nothing")
