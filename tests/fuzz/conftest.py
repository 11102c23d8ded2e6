"""Hypothesis profiles of the fuzz suite and the count of cases it ran.

The default profile ("ci") keeps tests/fuzz under about a minute on a 2-core host. The long
run: ``MESP_FUZZ=long pytest tests/fuzz`` (thousands of examples per property, ~hours).
"""

from __future__ import annotations

import os

import pytest
from hypothesis import HealthCheck, settings

from tests.fuzz.harness import COUNTS

settings.register_profile("ci", max_examples=50, deadline=None, derandomize=False,
                          suppress_health_check=[HealthCheck.too_slow,
                                                 HealthCheck.function_scoped_fixture])
settings.register_profile("long", max_examples=2000, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow,
                                                 HealthCheck.function_scoped_fixture])
settings.load_profile(os.environ.get("MESP_FUZZ", "ci"))


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    """Malformed inputs tried per kind, refused (one line, exit 2) and failed."""
    if not COUNTS:
        return
    terminalreporter.section("malformed inputs")
    kinds = sorted({k.split(": ")[0] for k in COUNTS})
    for kind in kinds:
        terminalreporter.write_line(
            f"{kind:18s} run {COUNTS[f'{kind}: run']:5d}  refused {COUNTS[f'{kind}: refused']:5d}"
            f"  failed {COUNTS[f'{kind}: failed']:3d}")
    total = sum(v for k, v in COUNTS.items() if k.endswith(": run"))
    failed = sum(v for k, v in COUNTS.items() if k.endswith(": failed"))
    terminalreporter.write_line(f"{'total':18s} run {total:5d}  failed {failed:3d}")
