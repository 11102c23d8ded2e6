"""Torn reads of the shared simulated clock under contention: one writer process pausing the
clock as fast as it can (far faster than the twin ever does), readers in this process reading
it, every value checked. The writer adds 1/1024 s per pause, so every whole value is a multiple
of 1/1024 and the values a reader sees never decrease; anything else is a torn read.

    PYTHONPATH=$PWD python bench/bench_sim_clock.py --reads 2000000              # this tree
    PYTHONPATH=$PWD python bench/bench_sim_clock.py --reads 2000000 --tree /work/main
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

STEP = 1.0 / 1024.0
WRITER = """\
import sys, time
from mesp_cell.drivers.sim_clock import SimClock
clock = SimClock(1.0, sys.argv[1])
print("ready", flush=True)
end = time.monotonic() + float(sys.argv[2])
while time.monotonic() < end:
    for _ in range(1000):
        clock.pause({step!r})
"""


@dataclass(frozen=True)
class Contention:
    """Outcome: reads made, torn (not a multiple of the step, or below the previous value),
    the largest jump back in simulated s, the writes seen (the last value / step)."""

    reads: int
    torn: int
    worst_s: float
    writes: int


def contend(reads: int, tree: Path, seconds: float = 60.0) -> Contention:
    """Read the clock ``reads`` times while a writer process (using ``tree``'s clock) pauses
    it without a break; stops the writer at the end."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    sys.path.insert(0, str(tree))
    from mesp_cell.drivers.sim_clock import SimClock

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "sim.clock"
        reader = SimClock(1.0, path, reset=True)
        writer = subprocess.Popen([sys.executable, "-c", WRITER.format(step=STEP), str(path),
                                   str(seconds)], env=env, stdout=subprocess.PIPE, text=True)
        try:
            assert writer.stdout is not None and writer.stdout.readline().strip() == "ready"
            torn, worst, last = 0, 0.0, 0.0
            for _ in range(reads):
                value = reader.paused()
                k = value / STEP
                if k != round(k) or value < last:
                    torn += 1
                    worst = max(worst, abs(last - value))
                else:
                    last = value
            return Contention(reads, torn, worst, round(last / STEP))
        finally:
            writer.kill()
            writer.wait()
            reader.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reads", type=int, default=2_000_000)
    ap.add_argument("--tree", type=Path, default=Path("."))
    args = ap.parse_args()
    start = time.perf_counter()
    out = contend(args.reads, args.tree.resolve())
    print(f"{out.reads} reads, {out.torn} torn (worst jump {out.worst_s:.3g} s), "
          f"{out.writes} writes seen, {time.perf_counter() - start:.1f} s")
    return 0 if out.torn == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
