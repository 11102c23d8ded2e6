"""``report.json`` of a job directory: each command adds its own section."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from core.artifacts import read_json, write_json

REPORT_FILE = "report.json"


def update_report(job_dir: Path, sections: Mapping[str, Any]) -> dict[str, Any]:
    """Merge ``sections`` into ``job_dir/report.json`` (top-level keys replaced) and save it."""
    path = Path(job_dir) / REPORT_FILE
    report = read_json(path)
    report.update(sections)
    write_json(path, report)
    return report


def read_report(job_dir: Path) -> dict[str, Any]:
    """The job's report, empty if none was written yet."""
    return read_json(Path(job_dir) / REPORT_FILE)
