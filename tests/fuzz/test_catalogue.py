"""Every named malformed input of tests/fuzz/cases.py is refused with exit 2 and one line."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.fuzz.cases import ALL_CASES, Case
from tests.fuzz.harness import assert_refused


@pytest.mark.parametrize("case", ALL_CASES, ids=lambda c: f"{c.kind}: {c.name}")
def test_refused_with_one_line(case: Case, tmp_path: Path) -> None:
    argv = case.build(tmp_path)
    assert_refused(argv, tmp_path, out_dirs=("out", "job", "logs"), kind=f"catalogue {case.kind}")
