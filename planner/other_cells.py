"""The bundled cells as a checked fix: where a job is refused in one cell, plan it in the others.

A refusal's fix must be one that works when followed. Where the cause lies with the cell (a
wall, reach, the gel), another bundled cell (``planner/cells/*.toml``, e.g. the shallow tray
for flat parts) may print the part: ``try_cells`` plans the job in each one the user did not
use and says which planned "ok" (the full plan, verification included) and why the others
refused, so the fix names a cell only when it was seen to work.
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path
from typing import NamedTuple

from core.errors import InputError
from core.stages import Toolpath
from planner.cell import CellConfig, load_cell
from planner.plan import plan
from planner.status import PlanStatus, Refused


class CellTrial(NamedTuple):
    """One bundled cell tried on a job.

    Attributes:
        path: the cell file (as the user would pass it to --cell; None for the default).
        name: its short name ("default", "tray").
        ok: the job planned with status ok there.
        reason: the plan's status or the refusal's problem (one line).
    """

    path: Path | None
    name: str
    ok: bool
    reason: str


def bundled_cells() -> list[tuple[str, Path | None]]:
    """(name, path) of every bundled cell; the default cell's path is None (no --cell)."""
    folder = Path(str(resources.files("planner").joinpath("cells")))
    out: list[tuple[str, Path | None]] = [("default", None)]
    for f in sorted(folder.glob("*.toml")):
        if f.stem != "default":
            out.append((f.stem, f))
    return out


def shown(path: Path | None) -> str:
    """A path as short as it can be said from the working directory."""
    if path is None:
        return "the default cell"
    rel = os.path.relpath(path)
    return rel if not rel.startswith("..") else str(path)


def try_cells(toolpath: Toolpath, used: Path | None) -> list[CellTrial]:
    """Plan ``toolpath`` in every bundled cell but ``used`` (None: the default), in order,
    stopping at the first that plans ok."""
    trials: list[CellTrial] = []
    used_real = None if used is None else Path(used).resolve()
    for name, path in bundled_cells():
        if (path is None and used is None) or (path is not None and path.resolve() == used_real):
            continue
        cell: CellConfig = load_cell(path)
        try:
            result = plan(toolpath, cell)
        except Refused as exc:
            trials.append(CellTrial(path, name, False, f"refused ({exc.cause})"))
            continue
        except InputError as exc:
            trials.append(CellTrial(path, name, False, exc.problem.split(":")[0]))
            continue
        ok = result.status == PlanStatus.OK
        trials.append(CellTrial(path, name, ok, str(result.status) if not ok else "ok"))
        if ok:
            break
    return trials


def checked_fix(trials: list[CellTrial], fallback: str) -> str:
    """The fix to print: the cell that planned ok, else ``fallback`` marked as not checked
    (re-slicing or changing the cell was not tried) and what was tried."""
    good = [t for t in trials if t.ok]
    if good:
        t = good[0]
        flag = "without --cell" if t.path is None else f"with --cell {shown(t.path)}"
        return f"plan {flag} (checked: the job plans ok in the {t.name} cell)"
    if not trials:
        return f"{fallback} (not checked)"
    tried = ", ".join(f"{t.name}: {t.reason}" for t in trials)
    return f"{fallback} (not checked; no bundled cell plans it either: tried {tried})"
