"""The ink a job's toolpath deposits (mm^3): what the print check and the console compare the
extruder's totaliser against. One function both the nodes and the web console use, so neither
imports the other."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def planned_ink(job_dir: Path) -> float:
    """mm^3 the toolpath deposits: the slicer's report, else from ``toolpath.npz``."""
    report = job_dir / "report.json"
    if report.is_file():
        try:
            vol = json.loads(report.read_text()).get("toolpath", {}).get("deposited_volume_mm3")
            if vol:
                return float(vol)
        except (OSError, ValueError):
            pass
    tp = job_dir / "toolpath.npz"
    if not tp.is_file():
        return 0.0
    with np.load(tp) as z:
        pos, path, ext = z["position"], z["path"], z["extrude"].astype(bool)
        w, h = z["width"], z["height"]
    seg = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    same = (path[1:] == path[:-1]) & ext[1:] & ext[:-1]
    area = 0.5 * (w[1:] * h[1:] + w[:-1] * h[:-1])
    return float(np.sum(seg * area * same))
