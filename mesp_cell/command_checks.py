"""Arguments of the commands that move the robot or drive the extruder, checked at the node
that receives them (after the sender, ``command_policy``).

* extruder ``start``/``set_rate``: a finite rate within the extruder's range
  (``slicer/ranges.toml`` ``[profile] setpoint_mm3_s``, the one owner of that range; a
  ``set_rate`` that follows the arm's speed may go down to 0);
* robot ``load``: the trajectory keeps the cell's clearance (``[planning] clearance_mm``) from
  the arm to the cell at every sample (the planner's collision model, gel as the job filled it);
* robot ``stream``: the first streamed sample is where the arm is (within ``START_TOL_DEG``):
  a stream never makes the servo target jump; ``move`` to the sample first.
"""

from __future__ import annotations

import math
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from core.tolerance import tol
from mesp_cell.messages import Command

START_TOL_DEG = 1.0  # deg, largest joint difference between the arm and a stream's first sample
MAX_CHECKED = 400_000  # trajectory samples checked for clearance (evenly spread above)


@cache
def rate_range() -> tuple[float, float]:
    """The accepted extruder set-point range, mm^3/s (``slicer/ranges.toml``)."""
    from slicer.config import job_ranges

    lo, hi = job_ranges()["profile.setpoint_mm3_s"]
    return float(lo), float(hi)


def rate_refusal(cmd: Command) -> str:
    """'' if an extruder command's rate is acceptable, else why not."""
    if cmd.verb not in ("start", "set_rate"):
        return ""
    raw = cmd.arg("rate")
    if isinstance(raw, bool) or not isinstance(raw, (int, float)):
        return f"{cmd.verb} needs a numeric rate in mm^3/s, got {raw!r}"
    lo, hi = rate_range()
    # following the arm's speed (flow sync) may ask for less than a set-point, never less than 0
    lo = lo if cmd.verb == "start" else 0.0
    if not math.isfinite(raw) or not lo <= raw <= hi:
        return (f"rate {raw} mm^3/s outside [{lo:g}, {hi:g}] "
                "(slicer/ranges.toml [profile] setpoint_mm3_s)")
    return ""


def clearance_refusal(q: np.ndarray, collision: Any, required_mm: float) -> str:
    """'' if every configuration of ``q`` (M, 6) rad keeps ``required_mm`` from the cell,
    else where it does not. Above ``MAX_CHECKED`` samples, an even spread of them."""
    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or q.shape[1] != 6 or not np.isfinite(q).all():
        return "trajectory joints are not finite (M, 6) values"
    idx = np.unique(np.linspace(0, len(q) - 1, min(len(q), MAX_CHECKED)).round().astype(int))
    clear = collision.clearance(q[idx])
    worst = int(np.argmin(clear.distance))
    if clear.distance[worst] < required_mm - tol.computed:
        return (f"trajectory sample {idx[worst]} comes {clear.distance[worst]:.1f} mm from the "
                f"cell ({clear.names[clear.pair[worst]]}), under the required {required_mm:g} mm")
    return ""


def load_refusal(node: Any, cmd: Command) -> str:
    """'' if the robot may load ``cmd``'s trajectory, else why not (clearance)."""
    path = Path(cmd.path)
    try:
        with np.load(path) as data:
            q = np.asarray(data["q"])
    except (OSError, KeyError, ValueError) as exc:
        return f"cannot read trajectory {path} ({exc})"
    reach = node._reach(path.parent)
    why = clearance_refusal(q, reach.collision, node.cell.planning.clearance_mm)
    if not why:
        node.reach = reach
    return why


def stream_refusal(node: Any, cmd: Command) -> str:
    """'' if a stream of ``cmd`` starts where the arm is, else how far it is."""
    plan = node.plan
    if plan is None or cmd.job_id != node.job_id:
        return ""  # the node refuses it itself (nothing loaded)
    start = cmd.arg("start", 0)
    if isinstance(start, bool) or not isinstance(start, int) or not 0 <= start < plan.samples:
        return f"stream start {start!r} is not a sample of the trajectory"
    diff = np.degrees(np.abs(np.asarray(plan.q_at(start)) - np.asarray(node.driver.joints())))
    j = int(np.argmax(diff))
    if diff[j] > START_TOL_DEG:
        return (f"stream would start {diff[j]:.1f} deg from the arm's pose (joint {j + 1}), "
                f"more than {START_TOL_DEG:g} deg; move to sample {start} first")
    return ""
