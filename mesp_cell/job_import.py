"""What a job may be made of: files copied from the import folders, profiles from the profile
folders.

A job never points at a caller's file. ``JobStore.submit`` copies the model (and the job and
cell files) into the job's own folder, and takes them only from an import folder
(``import_dirs``): ``$MESP_HOME/import``, the console's uploads (``$MESP_HOME/jobs/uploads``)
and the folders in ``$MESP_IMPORT_DIRS`` (separated by ``:``). A file is taken only if its real
path (links followed) is a regular file inside the same import folder, so a link to
``/etc/shadow`` or to the cell's secret is refused. ``mesp job submit`` (the operator, with
their own permissions) first copies the file it is given into a fresh ``$MESP_HOME/import``
folder (``import_file``). A job's ``[extrusion] profile`` may only be ``active``, a bundled
profile or a file in the lab's or the bundled profile folders (``profile_refusal``).
"""

from __future__ import annotations

import os
import re
import secrets
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

from core.errors import InputError
from mesp_cell.bus.secret import private_dir

if TYPE_CHECKING:
    from mesp_cell.jobs import JobRecord, JobStore

CHUNK = 1 << 20


def import_dirs(home: Path) -> list[Path]:
    """The folders a job's files may come from (real paths)."""
    dirs = [Path(home) / "import", Path(home) / "jobs" / "uploads"]
    extra = os.environ.get("MESP_IMPORT_DIRS", "")
    dirs += [Path(p) for p in extra.split(os.pathsep) if p]
    return [d.resolve() for d in dirs]


def inside(path: Path, folder: Path) -> bool:
    """``path`` (a real path) lies in ``folder`` (a real path)."""
    return path == folder or folder in path.parents


def importable(path: Path, home: Path, what: str) -> Path:
    """The real path of ``path`` if it is a regular file inside an import folder, with its real
    path in the same folder; else a one-line ``InputError``."""
    path = Path(path).absolute()
    real = path.resolve()
    for folder in import_dirs(home):
        if inside(path.parent.resolve(), folder):
            if not inside(real, folder):
                raise InputError(f"{what} {path} is a link to {real}, outside the import "
                                 f"folder {folder}", "copy the file itself into the folder")
            if not real.is_file():
                raise InputError(f"{what} {path} is not a regular file", "check the path")
            return real
    raise InputError(f"{what} {path} is not in an import folder",
                     f"submit it with `mesp job submit` (it copies it into {home / 'import'}) "
                     "or add its folder to MESP_IMPORT_DIRS")


def copy_into(src: Path, dst: Path) -> Path:
    """Copy the regular file ``src`` to the new file ``dst`` (mode 0600) without following a
    link at ``src`` (``O_NOFOLLOW`` closes the race between the check and the open)."""
    with os.fdopen(os.open(src, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0)), "rb") as fin, \
            os.fdopen(os.open(dst, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600), "wb") as fout:
        shutil.copyfileobj(fin, fout, CHUNK)
    return dst


def import_file(path: Path, home: Path, what: str) -> Path:
    """Copy an operator's file into a fresh import folder; the copy's path. A link that leaves
    its own folder is refused (it would hand over a file the operator did not name)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{what} {path} does not exist", "check the path")
    if path.is_symlink():
        target = path.resolve()
        if target.parent != path.absolute().parent.resolve():
            raise InputError(f"{what} {path} is a link to {target}, outside its folder",
                             "copy the file itself into the folder you submit from")
    folder = private_dir(private_dir(Path(home) / "import") / secrets.token_hex(8))
    return copy_into(path.resolve(), folder / safe_name(path.name))


def safe_name(name: str) -> str:
    """A file name reduced to ``[a-z0-9-]`` plus its suffix (no path from a caller is kept)."""
    p = Path(name)
    stem = re.sub(r"[^a-z0-9]+", "-", p.stem.lower()).strip("-")[:40] or "model"
    suffix = p.suffix.lower() if re.fullmatch(r"\.[a-z0-9]{1,8}", p.suffix.lower()) else ""
    return stem + suffix


def profile_refusal(profile: str, home: Path) -> str:
    """'' if a job's ``[extrusion] profile`` names a profile of the profile folders, else why
    not: ``active``, a bundled name, or a ``.toml`` inside ``$MESP_HOME/profiles`` or the
    bundled ``slicer/profiles``."""
    from slicer.extrusion import ACTIVE
    from slicer.profiles import bundled_names

    if profile == ACTIVE or profile in bundled_names():
        return ""
    real = Path(profile).expanduser().resolve()
    folders = [(Path(home) / "profiles").resolve(),
               (Path(__file__).resolve().parent.parent / "slicer" / "profiles").resolve()]
    if real.suffix == ".toml" and any(inside(real, f) for f in folders):
        return ""
    return (f"extrusion profile '{profile}' is not in a profile folder "
            f"({', '.join(str(f) for f in folders)})")


def submit_copies(store: JobStore, cell: str, home: Path, model: Path,
                  job_file: Path | None = None, cell_file: Path | None = None) -> JobRecord:
    """Queue a job from an operator's files: each copied into a fresh import folder
    (``import_file``), then into the job's folder by ``store.submit``; the import copies are
    removed again."""
    staged: list[Path] = []
    try:
        m = import_file(Path(model), home, "model")
        staged.append(m)
        j = import_file(Path(job_file), home, "job file") if job_file is not None else None
        staged += [j] if j is not None else []
        c = import_file(Path(cell_file), home, "cell file") if cell_file is not None else None
        staged += [c] if c is not None else []
        return store.submit(m, cell, j, c)
    finally:
        for path in staged:
            shutil.rmtree(path.parent, ignore_errors=True)
