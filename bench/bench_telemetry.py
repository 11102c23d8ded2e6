"""Size of a print's telemetry file per hour (docs/telemetry.md).

Feeds ``JobRecorder`` robot and extruder states as the cell publishes them (100 Hz each, values
that change like a print's) for ``--hours`` of print and reports the MCAP file's size.

    python bench/bench_telemetry.py --hours 0.25 --record-hz 20
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from mesp_cell.messages import ExtruderState, RobotState
from mesp_cell.telemetry import JobRecorder


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--hours", type=float, default=0.25)
    ap.add_argument("--record-hz", type=float, default=20.0)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    hz = 100.0
    n = int(hz * 3600 * args.hours)
    tcp = rng.normal(0.0, 100.0, (1000, 3))
    q = np.cumsum(rng.normal(0.0, 0.01, (n, 6)), axis=0)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "t.mcap"
        rec = JobRecorder(path, tcp, record_hz=args.record_hz)
        start = time.perf_counter()
        for k in range(n):
            t = 1.7e9 + k / hz
            rec.record(RobotState(t, k, tuple(q[k].round(4)), tuple((0.1 * q[k]).round(4)),
                                  tuple((tcp[k % 1000] + 0.01 * k).round(4)), "streaming",
                                  "job-0001", k % 1000, 1000, k // 10, True, False, "", 0.0))
            rec.record(ExtruderState(t, k, 6.57, 6.57 + rng.normal(0.0, 0.05), 6.57 * k / hz,
                                     True, True, 0, ""))
        rec.close()
        size = path.stat().st_size / 1e6
    print(f"{args.hours:g} h of 100 Hz states kept at {args.record_hz:g} Hz: {size:.2f} MB "
          f"({size / args.hours:.1f} MB/h), JSON {rec.bytes / 1e6:.1f} MB before zstd, "
          f"written in {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
