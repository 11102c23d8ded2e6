"""A job taken elsewhere: one zip of its report, figures, preview, exports and telemetry.

The stage arrays (``*.npz``) stay out: they are large and ``mesp slice``/``mesp plan`` make them
again; what a person reviewing a print needs is what it looked like and what the cell recorded.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

from core.errors import InputError

PATTERNS = ("report.json", "job.toml", "preview.html", "telemetry*.mcap", "inspect_*.png",
            "figures/*", "export/*", "baseline_*.gcode")


def bundle_files(job_dir: Path) -> list[Path]:
    """The files of ``job_dir`` a bundle holds, in a stable order."""
    job_dir = Path(job_dir)
    found = {p for pattern in PATTERNS for p in job_dir.glob(pattern) if p.is_file()}
    return sorted(found)


def bundle_job(job_dir: Path, out: Path) -> tuple[Path, list[Path]]:
    """Write ``out`` (zip, paths relative to the job directory); returns it and its files.

    Raises:
        InputError: the job directory is missing or holds nothing to bundle.
    """
    job_dir = Path(job_dir)
    if not job_dir.is_dir():
        raise InputError(f"job directory {job_dir} does not exist",
                         "the job was never sliced; see `mesp job status`")
    files = bundle_files(job_dir)
    if not files:
        raise InputError(f"{job_dir} holds no report, figures or telemetry yet",
                         "export the job once it was sliced or printed")
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".part")
    with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for f in files:
            # MCAP chunks, PNG and MP4 are compressed already
            packed = f.suffix in (".mcap", ".png", ".mp4")
            z.write(f, f.relative_to(job_dir).as_posix(),
                    compress_type=zipfile.ZIP_STORED if packed else zipfile.ZIP_DEFLATED)
    tmp.replace(out)
    return out, files
