"""Uploaded jobs: size-limited, stored under generated names inside the cell's job directory,
checked before they are queued.

No name a client sends is ever used as a path: the model is stored as
``$MESP_HOME/jobs/uploads/<random>/<stem><suffix>``, the stem reduced to lower-case letters,
digits and '-' (it names the job), the suffix one of the supported types; the job file becomes
``job.toml`` beside it.
"""

from __future__ import annotations

import re
import secrets
import shutil
from pathlib import Path, PurePosixPath
from typing import BinaryIO

from core.errors import InputError
from mesp_cell.jobs import check_submission
from slicer.mesh_io import SURFACE_SUFFIXES, TET_SUFFIXES

CHUNK = 1 << 16
MODEL_SUFFIXES = SURFACE_SUFFIXES + TET_SUFFIXES  # what the slicer reads


class TooLarge(InputError):
    """An upload beyond the console's size limit."""


def model_suffix(filename: str | None) -> str:
    """The supported suffix of an uploaded model's name, or an InputError."""
    suffix = PurePosixPath((filename or "").replace("\\", "/")).suffix.lower()
    if suffix not in MODEL_SUFFIXES:
        raise InputError(f"model '{filename}' has an unsupported type '{suffix}'",
                         f"upload one of {', '.join(MODEL_SUFFIXES)}")
    return suffix


def safe_stem(filename: str | None) -> str:
    """A file stem made only of ``[a-z0-9-]`` (at most 40), from the client's name."""
    stem = PurePosixPath((filename or "").replace("\\", "/")).stem.lower()
    return re.sub(r"[^a-z0-9]+", "-", stem).strip("-")[:40].strip("-") or "model"


def copy_limited(src: BinaryIO, dst: Path, limit: int, what: str) -> int:
    """Copy ``src`` to ``dst``, refusing more than ``limit`` bytes; returns the size."""
    size = 0
    with open(dst, "wb") as out:
        while True:
            chunk = src.read(CHUNK)
            if not chunk:
                break
            size += len(chunk)
            if size > limit:
                raise TooLarge(f"{what} is larger than {limit // (1 << 20)} MiB",
                               "upload a smaller file or raise the console's max_upload_mb")
            out.write(chunk)
    return size


def store_upload(root: Path, model: BinaryIO, model_name: str | None, job: BinaryIO | None,
                 limit: int) -> tuple[Path, Path | None]:
    """Save an upload under a new directory of ``root`` and check it (``check_submission``);
    returns (model path, job file path or None). Nothing is left behind when refused."""
    suffix = model_suffix(model_name)
    folder = Path(root) / "uploads" / secrets.token_hex(8)
    folder.mkdir(parents=True)
    try:
        model_path = folder / f"{safe_stem(model_name)}{suffix}"
        copy_limited(model, model_path, limit, "the model")
        job_path = None
        if job is not None:
            job_path = folder / "job.toml"
            if copy_limited(job, job_path, limit, "the job file") == 0:
                job_path.unlink()
                job_path = None
        check_submission(model_path, job_path)
    except InputError as exc:
        shutil.rmtree(folder, ignore_errors=True)
        # the client's own names in the answer, not the cell's folders
        named = {str(folder / p): n for p, n in (("job.toml", "the job file"),)}
        named[str(model_path)] = f"model '{safe_stem(model_name)}{suffix}'"

        def mask(text: str) -> str:
            for path, name in named.items():
                text = text.replace(f"model {path}", name).replace(path, name)
            return text

        raise type(exc)(mask(exc.problem), mask(exc.fix)) from exc
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    return model_path, job_path
