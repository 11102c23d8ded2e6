"""The nozzle acceleration a toolpath may ask for where its speed changes within a path.

The slicer changes the nozzle speed inside a path where it changes the width (W = C / (H v)):
the stripe joins print narrower, so faster (``slicer.toolpath.stripe_joins``). The arm
reaches a speed change only as fast as its joint accelerations allow, and at a turn, where
the wrist turns with the path, that is far less than on a straight line. The value is a cell
setting: it lives in the cell file (``[planning] path_accel_mm_s2``); the slicer shapes its
speed ramps to the bundled cell's (``bundled_path_accel``), and the planner reports the
toolpath segments that ask more than the job's cell gives (``plan.path_accel`` in
report.json, ``planner.flow.asked_acceleration``).
"""

from __future__ import annotations

from core.toml_defaults import table


def bundled_path_accel() -> float:
    """mm/s^2, the path acceleration of the bundled cell (``planner/cells/default.toml``)."""
    return float(table("planner", "cells/default.toml", "planning")["path_accel_mm_s2"])
