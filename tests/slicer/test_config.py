"""Job configuration: defaults, overrides, and one-line errors naming the key."""

from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from slicer.config import CriticalSelector, JobConfig, load_job


def test_defaults_load_and_validate() -> None:
    job = load_job()
    assert isinstance(job, JobConfig)
    assert job.slicing.layer_height_mm > 0
    assert job.mesh.edge_length_mm > 0
    assert job.model.scale_mm == 1.0


def test_job_file_overrides_defaults(tmp_path: Path) -> None:
    path = tmp_path / "job.toml"
    path.write_text('[slicing]\nlayer_height_mm = 0.8\ncritical = ["top:30"]\n')
    job = load_job(path)
    assert job.slicing.layer_height_mm == 0.8
    assert job.slicing.selectors[0].direction == (0.0, 0.0, 1.0)
    assert job.mesh == JobConfig().mesh


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[slicing]\nlayer_hieght_mm = 0.8\n", "unknown key 'job.slicing.layer_hieght_mm'"),
        ("[slicing]\nlayer_height_mm = 'thin'\n", "must be a number"),
        ("[slicing]\nlayer_height_mm = -1\n", "layer_height_mm"),
        ("[model]\nunits = 'furlong'\n", "'job.model.units' is 'furlong'"),
        ("[slicing\n", "not valid TOML"),
        ("[slicing]\ncritical = ['sideways']\n", "not understood"),
        ("[toolpath]\nboundary_distance = 'exact'\n", "boundary_distance"),
        ("[toolpath]\nstripe_field = 'radial'\n", "stripe_field"),
        ("[toolpath]\ndeformation_tolerance = 0.5\n", "deformation_tolerance"),
        ("[toolpath]\nmax_step_elevation_deg = 20\n", "max_step_elevation_deg"),  # cell's now
        ("[slicing]\ncritical = ['bottom@q<1']\n", "condition '@q<1' is not understood"),
        ("[slicing]\ncritical = ['bottom@z<1e']\n", "bad number"),
    ],
)
def test_bad_job_file_is_one_line_input_error(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "job.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=message) as info:
        load_job(path)
    assert "\n" not in info.value.one_line()


def test_missing_job_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="does not exist"):
        load_job(tmp_path / "nope.toml")


@pytest.mark.parametrize(
    ("text", "direction", "cone"),
    [
        ("bottom", (0.0, 0.0, -1.0), 45.0),
        ("top:30", (0.0, 0.0, 1.0), 30.0),
        ("normal:2,0,0:10", (1.0, 0.0, 0.0), 10.0),
    ],
)
def test_critical_selector_parse(
    text: str, direction: tuple[float, float, float], cone: float
) -> None:
    sel = CriticalSelector.parse(text)
    assert sel.direction == direction and sel.cone_deg == cone


def test_selector_position_conditions() -> None:
    sel = CriticalSelector.parse("bottom:30@z<1@x>-5")
    assert sel.cone_deg == 30.0 and sel.where == ((2, "<", 1.0), (0, ">", -5.0))
    assert sel.accepts(np.array([0.0, 0.0, 0.5])) and not sel.accepts(np.array([0.0, 0.0, 2.0]))
    assert CriticalSelector.parse("top").where == ()


@pytest.mark.parametrize("text", ["top:95", "normal:0,0,0", "left", "top:x", "top@z=1"])
def test_bad_critical_selector(text: str) -> None:
    with pytest.raises(InputError):
        CriticalSelector.parse(text)


def test_with_overrides_validates() -> None:
    job = load_job()
    assert job.with_overrides(mesh={"edge_length_mm": 2.0}).mesh.edge_length_mm == 2.0
    with pytest.raises(InputError):
        job.with_overrides(mesh={"edge_length_mm": -2.0})


def test_every_number_is_finite_and_in_its_documented_range(tmp_path: Path) -> None:
    from slicer.config import job_ranges
    from slicer.extrusion import load_profile

    ranges = job_ranges()
    defaults = load_job()
    for key, (lo, hi) in ranges.items():  # the defaults lie within their ranges
        section, name = key.split(".")
        # [profile]: the rates of an extrusion profile, checked on the job's default profile
        owner = (load_profile(defaults.extrusion.profile) if section == "profile"
                 else getattr(defaults, section))
        value = getattr(owner, name)
        if isinstance(value, int | float):
            assert lo <= value <= hi, key
    job = tmp_path / "job.toml"
    job.write_text("[slicing]\nsmoothness_weight = nan\n")
    with pytest.raises(InputError, match=r"smoothness_weight.*finite"):
        load_job(job)
    job.write_text("[slicing]\nlayer_height_mm = 0.01\n")
    with pytest.raises(InputError, match=r"outside 0\.05 to 20.*ranges\.toml"):
        load_job(job)
    job.write_text("[extrusion]\nprofile = \"/etc/passwd\"\n")
    with pytest.raises(InputError, match="profile"):
        load_job(job)
