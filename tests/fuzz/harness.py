"""Running `mesp` in this process on a malformed input and judging the outcome.

``run`` calls ``mesp_cell.cli.main`` with a time bound (SIGALRM), in a directory of its own
with ``MESP_HOME`` inside it, and returns what a user would see. ``assert_refused`` is the
property every malformed input must have: exit 2, exactly one stderr line ``mesp: error:
<problem>; <fix>``, no traceback, within the time bound, nothing written outside the
directory, no partial stage file. ``COUNTS`` tallies cases run and outcomes for the session
summary (tests/fuzz/conftest.py).
"""

from __future__ import annotations

import collections
import contextlib
import io
import os
import signal
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mesp_cell.cli import main

#: Seconds one malformed input may take before it counts as a hang.
TIME_LIMIT_S = 30
COUNTS: collections.Counter[str] = collections.Counter()


class Hang(Exception):
    """The command ran past the time limit."""


@dataclass(frozen=True)
class Outcome:
    """What a user saw: exit code, stderr, and files created under the working directory."""

    code: int
    stderr: str
    created: tuple[Path, ...]


@contextlib.contextmanager
def _alarm(seconds: int) -> Iterator[None]:
    def ring(signum: int, frame: object) -> None:
        raise Hang(f"no answer within {seconds} s")

    old = signal.signal(signal.SIGALRM, ring)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def _files(root: Path) -> set[Path]:
    return {p for p in root.rglob("*") if p.is_file() or p.is_symlink()}


def run(argv: list[str], cwd: Path, time_limit: int = TIME_LIMIT_S) -> Outcome:
    """``mesp ARGV`` in ``cwd`` (its own ``MESP_HOME``); a library's exit is an exit code."""
    before = _files(cwd)
    err = io.StringIO()
    old_cwd, old_home = Path.cwd(), os.environ.get("MESP_HOME")
    os.chdir(cwd)
    os.environ["MESP_HOME"] = str(cwd / "home")
    try:
        with _alarm(time_limit), contextlib.redirect_stderr(err), \
                contextlib.redirect_stdout(io.StringIO()):
            try:
                code = main(argv)
            except SystemExit as exc:  # argparse, or a library calling sys.exit
                code = exc.code if isinstance(exc.code, int) else 1
    finally:
        os.chdir(old_cwd)
        if old_home is None:
            os.environ.pop("MESP_HOME", None)
        else:
            os.environ["MESP_HOME"] = old_home
    return Outcome(int(code or 0), err.getvalue(), tuple(sorted(_files(cwd) - before)))


def assert_one_line(outcome: Outcome) -> None:
    """Exit 2 with exactly one line ``mesp: error: <problem>; <fix>`` on stderr."""
    lines = [x for x in outcome.stderr.splitlines() if x.strip()]
    assert outcome.code == 2, f"exit {outcome.code}, stderr: {outcome.stderr[-500:]}"
    assert len(lines) == 1, f"{len(lines)} stderr lines: {outcome.stderr[-500:]}"
    assert lines[0].startswith("mesp: error: ") and "; " in lines[0], lines[0]
    assert "Traceback" not in outcome.stderr


def assert_clean(outcome: Outcome, cwd: Path, out_dirs: tuple[str, ...]) -> None:
    """Nothing written outside ``out_dirs`` (relative to ``cwd``) or the home, no temporary
    or partial stage file left."""
    allowed = [cwd / d for d in (*out_dirs, "home")]
    for path in outcome.created:
        assert any(path.is_relative_to(a) for a in allowed), f"wrote {path}"
        assert not path.name.endswith(".tmp"), f"left a partial file {path}"
        if path.suffix == ".npz":
            with np.load(path) as data:  # a stage file is whole or absent
                assert data.files, f"empty stage file {path}"


def assert_refused(argv: list[str], cwd: Path, out_dirs: tuple[str, ...] = ("out",),
                   kind: str = "") -> Outcome:
    """The property of a malformed input (see the module docstring); counted in ``COUNTS``."""
    COUNTS[f"{kind or argv[0]}: run"] += 1
    try:
        outcome = run(argv, cwd)
        assert_one_line(outcome)
        assert_clean(outcome, cwd, out_dirs)
        COUNTS[f"{kind or argv[0]}: refused"] += 1
    except BaseException:
        COUNTS[f"{kind or argv[0]}: failed"] += 1
        raise
    return outcome


def judge(argv: list[str], cwd: Path, out_dirs: tuple[str, ...] = ("out",),
          kind: str = "") -> Outcome:
    """For a mutated input that may still be valid: exit 0, or refused as above."""
    COUNTS[f"{kind or argv[0]}: run"] += 1
    try:
        outcome = run(argv, cwd)
        if outcome.code != 0:
            assert_one_line(outcome)
            COUNTS[f"{kind or argv[0]}: refused"] += 1
        assert_clean(outcome, cwd, out_dirs)
    except BaseException:
        COUNTS[f"{kind or argv[0]}: failed"] += 1
        raise
    return outcome
