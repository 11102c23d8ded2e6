"""When a print is done: every waypoint printed exactly once and the toolpath's ink delivered.

A stream that reached its last sample is not yet a finished part: a resume may have skipped or
repeated waypoints, and an extruder may have turned without delivering. ``check_print`` reads
the robot's ledger (``print_ledger``: the deposition waypoints it passed, in order) and the ink
the totaliser counted for the part (total, less the ink extruded with the nozzle at rest: the
purge and the resume leads, and on a fast twin the ink its extruder switches' wall-clock
latency moved in simulated time, ``extruder_switch``) and compares them with the trajectory's
deposition waypoints and the toolpath's volume (``planned_ink``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mesp_cell.drivers.stream import StreamPlan
from mesp_cell.nodes import print_ledger
from mesp_cell.planned_ink import planned_ink

#: relative difference allowed between the ink extruded for the part and the toolpath's
#: volume (the slicer matches the toolpath's volume to the model's within the same 2 %)
VOLUME_TOLERANCE = 0.02


@dataclass(frozen=True)
class PrintCheck:
    """The verdict on a finished stream.

    Attributes:
        expected: deposition waypoints of the trajectory. printed: reports in the ledger.
        missing: waypoints never reported. doubled: extra reports plus printed waypoints a
            later stream went over again.
        part_mm3: ink for the part (totaliser less ink at rest), mm^3. toolpath_mm3: mm^3.
        stop_mm3: mm^3 the ink around the stops is uncertain by: per resumed stop, the ink of
            the screw's lead (the set-point x ``lead_s``; where in it the screw stopped is
            known to the servo sample, when it stopped to the bus and Modbus latency).
        switch_mm3: mm^3 a fast twin's switch latency moved beyond real time, taken off the
            totaliser's ink to give ``part_mm3`` (0 on the real cell).
    """

    expected: int
    printed: int
    missing: int
    doubled: int
    part_mm3: float
    toolpath_mm3: float
    stop_mm3: float = 0.0
    switch_mm3: float = 0.0

    @property
    def volume_error(self) -> float:
        """part / toolpath - 1 (inf without a toolpath volume)."""
        return self.part_mm3 / self.toolpath_mm3 - 1 if self.toolpath_mm3 > 0 else float("inf")

    @property
    def ok(self) -> bool:
        return (not self.missing and not self.doubled
                and abs(self.part_mm3 - self.toolpath_mm3)
                <= VOLUME_TOLERANCE * self.toolpath_mm3 + self.stop_mm3)

    @property
    def reason(self) -> str:
        """Why the job is not done ("" if it is)."""
        if self.missing:
            return (f"{self.missing} of {self.expected} waypoints were never reported printed "
                    "by the robot")
        if self.doubled:
            return f"{self.doubled} waypoints were printed twice"
        if not self.ok:
            return (f"the part got {self.part_mm3:.1f} mm^3 of ink, the toolpath needs "
                    f"{self.toolpath_mm3:.1f} mm^3 ({100 * self.volume_error:+.1f} %, more than "
                    f"{100 * VOLUME_TOLERANCE:.0f} % + {self.stop_mm3:.1f} mm^3 for its stops)")
        return ""

    @property
    def fix(self) -> str:
        if self.missing or self.doubled:
            return "inspect the part; re-submit the job for a new part"
        return ("check the extruder (clogged nozzle, empty cartridge, slipping screw) and its "
                "calibration (`mesp calibrate extrusion`), then re-submit the job")

    def report(self) -> dict[str, Any]:
        """The verdict for ``report.json``."""
        return {"waypoints_expected": self.expected, "waypoints_printed": self.printed,
                "waypoints_missing": self.missing, "waypoints_doubled": self.doubled,
                "part_volume_mm3": self.part_mm3, "toolpath_volume_mm3": self.toolpath_mm3,
                "stop_allowance_mm3": self.stop_mm3,
                "switch_latency_mm3": self.switch_mm3,
                "volume_error": self.volume_error}


def check_print(job_dir: Path, plan: StreamPlan, volume_mm3: float, rest_mm3: float,
                lead_mm3: float = 0.0, true_per_nominal: float = 1.0) -> PrintCheck:
    """The verdict on ``job_dir``'s print: ``volume_mm3`` extruded in all, ``rest_mm3`` of it
    with the nozzle at rest; ``lead_mm3``: the set-point's ink over the screw's lead;
    ``true_per_nominal``: mm^3 delivered per nominal mm^3 of the totaliser (the profile's)."""
    printed = print_ledger.read(job_dir)
    expected = plan.wp_id[np.asarray(plan.wp_extrude, dtype=bool)]
    resumes = int(np.count_nonzero(printed.streams[:, 1] >= 0)) if printed.streams.size else 0
    switch_mm3 = printed.switch_mm3 * true_per_nominal
    return PrintCheck(int(expected.size), int(printed.waypoints.size),
                      int(printed.missing(expected).size),
                      printed.doubled + printed.restreamed(),
                      volume_mm3 - rest_mm3 - switch_mm3, planned_ink(Path(job_dir)),
                      resumes * lead_mm3, switch_mm3)
