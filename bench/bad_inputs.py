"""Every malformed input of the catalogue (tests/fuzz/cases.py) run as its own `mesp` process
against a checkout, each outcome counted: error (exit 2 and one line ``mesp: error: ...; ...``),
traceback, hang (past the time limit), accepted (exit 0) or wrong exit.

    PYTHONPATH=$PWD python bench/bad_inputs.py --tree /work/main      # before
    PYTHONPATH=$PWD python bench/bad_inputs.py --tree .               # after

Children run with a 6 GiB address-space limit (an exhausted memory is a MemoryError, not a
swapping machine), in a fresh directory with ``MESP_HOME`` inside it.
"""

from __future__ import annotations

import argparse
import collections
import os
import resource
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tests.fuzz.cases import ALL_CASES, Case

MEMORY_LIMIT = 6 << 30
RUN = "import sys; from mesp_cell.cli import main; sys.exit(main(sys.argv[1:]))"


def _limit() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def classify(code: int | None, stderr: str) -> str:
    """The outcome of one run: error | traceback | hang | accepted | wrong exit."""
    if code is None:
        return "hang"
    if "Traceback (most recent call last)" in stderr:
        return "traceback"
    lines = [x for x in stderr.splitlines() if x.startswith("mesp: error: ")]
    if code == 2 and len(lines) == 1 and "; " in lines[0]:
        return "error"
    return "accepted" if code == 0 else "wrong exit"


def run_case(case: Case, tree: Path, timeout: float) -> tuple[str, float, str]:
    """(outcome, seconds, last stderr line) of one case."""
    with tempfile.TemporaryDirectory(prefix="mesp-bad-") as name:
        tmp = Path(name)
        argv = case.build(tmp)
        env = {**os.environ, "PYTHONPATH": str(tree), "MESP_HOME": str(tmp / "home"),
               "MPLBACKEND": "Agg"}
        start = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-c", RUN, *argv], cwd=tmp, env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                preexec_fn=_limit, start_new_session=True)
        try:
            _, err = proc.communicate(timeout=timeout)
            code: int | None = proc.returncode
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGINT)  # a launcher stops its children on Ctrl-C
            try:
                _, err = proc.communicate(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                _, err = proc.communicate()
            code = None
        seconds = time.perf_counter() - start
    last = next((x for x in reversed(err.splitlines()) if x.strip()), "")
    return classify(code, err), seconds, last


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tree", type=Path, default=Path("."), help="checkout to run")
    ap.add_argument("--timeout", type=float, default=60.0, help="s per case before 'hang'")
    ap.add_argument("--only", default="", help="run the cases whose kind or name has this")
    args = ap.parse_args()
    counts: collections.Counter[str] = collections.Counter()
    for case in ALL_CASES:
        if args.only and args.only not in f"{case.kind} {case.name}":
            continue
        outcome, seconds, last = run_case(case, args.tree.resolve(), args.timeout)
        counts[outcome] += 1
        print(f"{outcome:10s} {seconds:6.1f}s  {case.kind:7s} {case.name}  | {last[:150]}",
              flush=True)
    total = sum(counts.values())
    print(f"{total} cases: " + ", ".join(f"{k} {v}" for k, v in counts.most_common()))
    return 0 if counts["error"] == total else 1


if __name__ == "__main__":
    sys.exit(main())
