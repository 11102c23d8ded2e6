"""A new extrusion profile from a base profile and calibration results (``mesp calibrate``).

The new profile keeps the base's material, beta and whatever it did not measure, takes the
measured values (C at the set-point and the density, or the morphology table), records how and
when each was measured under ``[calibration.*]``, and gets its own name: a calibrated profile is
a new file, never an edit of the old one, so jobs sliced with the old one stay identifiable.
"""

from __future__ import annotations

import tomllib
from datetime import datetime
from typing import Any

import tomli_w

from mesp_cell.calibration import RateFit
from mesp_cell.morphology_fit import MorphologyFit
from slicer.extrusion import ExtrusionProfile, profile_from_dict


def default_name(base: ExtrusionProfile, when: datetime) -> str:
    """``<material stem>-<date>``, the base's date suffix replaced (``ecoflex-0030-2026-11-27``)."""
    stem = base.name
    parts = stem.rsplit("-", 3)
    if len(parts) == 4 and all(p.isdigit() for p in parts[1:]):
        stem = parts[0]
    return f"{stem}-{when:%Y-%m-%d}"


def calibrated_text(base: ExtrusionProfile, name: str, when: datetime,
                    rate: RateFit | None = None, morphology: MorphologyFit | None = None,
                    command: str = "") -> str:
    """The TOML text of the new profile (validated as the slicer reads it)."""
    data: dict[str, Any] = tomllib.loads(base.text)
    stamp = when.isoformat(timespec="seconds")
    calib = dict(data.get("calibration", {}))
    notes = [str(data["provenance"])] if data.get("provenance") else []
    data["name"] = name
    data["date"] = stamp
    data["based_on"] = {"name": base.name, "sha256": base.sha256}
    if rate is not None:
        data["rate_mm3_s"] = round(rate.C, 4)
        data["setpoint_mm3_s"] = rate.setpoint
        data["density_g_cm3"] = rate.density
        data["calibrated"] = True
        calib["extrusion"] = {
            "date": stamp, "method": "weighed runs at the set-point, mass = rho (C t + V0)",
            "setpoint_mm3_s": rate.setpoint, "seconds": rate.seconds.tolist(),
            "mass_g": rate.mass.round(5).tolist(), "density_g_cm3": rate.density,
            "rate_mm3_s": round(rate.C, 5), "u_rate_mm3_s": round(rate.u_C, 5),
            "u95_rate_mm3_s": round(rate.expanded(0.95), 5),
            "startup_volume_mm3": round(rate.v0, 4),
            "residual_g": rate.residual_g.round(5).tolist(),
        }
        notes.append(f"C = {rate.C:.4g} +- {rate.u_C:.2g} mm^3/s at set-point "
                     f"{rate.setpoint:g} weighed {stamp}")
    if morphology is not None:
        m = morphology
        data["morphology"] = {
            "speed_mm_s": m.speed.round(4).tolist(),
            "filament_width_mm": m.width.round(4).tolist(),
            "filament_height_mm": m.height.round(4).tolist(),
        }
        calib["morphology"] = {
            "date": stamp, "samples": m.samples, "width_mm": [m.a_w, m.b_w],
            "height_mm": [m.a_h, m.b_h], "r2_width": round(m.r2_w, 6),
            "r2_height": round(m.r2_h, 6),
            "model": "w_f = a v^b, h_f = a v^b (v in mm/s, lengths in mm)",
        }
        notes.append(f"morphology fitted from {m.samples} measured filaments {stamp}")
    data["calibration"] = calib
    data["provenance"] = "; ".join(notes)
    head = f"# Extrusion profile written by {command or 'mesp calibrate'} on {stamp}.\n\n"
    text = head + tomli_w.dumps(data)
    profile_from_dict(tomllib.loads(text), name, text)  # refuse what the slicer would refuse
    return text
