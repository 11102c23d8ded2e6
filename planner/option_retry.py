"""Planning options the planner re-tries itself before it names them as a fix.

A refusal's fix must work when followed. Some refusals can be lifted by a ``[planning]``
setting of the cell rather than by re-slicing: more lean of the nozzle about its direction of
motion (a path whose arriving step climbs out of the layer while the leaving one stays in it,
a wall or the reach in the way of the nozzle on the printing direction), more turn towards
vertical (the wrist near the base axis), finer trajectory samples (a limit broken between
two samples). ``retry`` plans the job again with the options that address the refusal's
cause or status (``CANDIDATES``), each one a full plan with verification, and returns the
first that plans ok, or what it tried. A bend is first re-tested with the bend test alone
(``refusal.bends``, well under a second): only an option that serves every bent waypoint is
planned.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, NamedTuple

from core.errors import InputError
from core.stages import Toolpath
from planner.cell import CellConfig
from planner.plan import plan
from planner.printability import directions
from planner.refusal import bends
from planner.status import Cause, PlanStatus, Refused

ROOM = {"lean_max_deg": 60.0, "upright_max_deg": 45.0}  # the widest the cell ranges allow
CANDIDATES: dict[Cause | PlanStatus, tuple[dict[str, float], ...]] = {
    Cause.BEND: ({"lean_max_deg": 60.0},),
    Cause.REACH: (ROOM,),
    Cause.WALL: (ROOM,),
    Cause.GEL: (ROOM,),
    Cause.OBSTACLE: (ROOM,),
    PlanStatus.UNREACHABLE: (ROOM,),
    PlanStatus.UNREACHABLE_BETWEEN: (ROOM, {"max_step_mm": 0.5}),
    PlanStatus.CLEARANCE: (ROOM,),
    PlanStatus.SWING: ({"max_step_mm": 0.5},),
    PlanStatus.ALPHA: ({"max_step_mm": 0.5},),
    PlanStatus.JOINT_SPEED: ({"max_step_mm": 0.5},),
    PlanStatus.TCP_SPEED: ({"max_step_mm": 0.5},),
    PlanStatus.TIME_LAW: ({"max_step_mm": 0.5},),
}


class Retry(NamedTuple):
    """What ``retry`` found.

    Attributes:
        option: the ``[planning]`` settings with which the job planned ok (None if none).
        tried: one line per option tried: the settings and what came of them.
    """

    option: dict[str, float] | None
    tried: tuple[str, ...]


def _text(option: dict[str, float]) -> str:
    return ", ".join(f"{k} = {v:g}" for k, v in option.items())


def _widens(cell: CellConfig, option: dict[str, float]) -> bool:
    """``option`` gives the planner more room than ``cell`` (larger angles, finer samples)."""
    return any(v < getattr(cell.planning, k) if k == "max_step_mm"
               else v > getattr(cell.planning, k) for k, v in option.items())


def retry(toolpath: Toolpath, cell: CellConfig, why: Cause | PlanStatus) -> Retry:
    """Plan ``toolpath`` in ``cell`` with each candidate option for ``why`` (the refusal's
    cause, or the status of a plan that is not ok) that changes the cell, until one plans ok."""
    tried: list[str] = []
    for option in CANDIDATES.get(why, ()):
        if not _widens(cell, option):
            continue  # the cell already allows this much
        settings: dict[str, Any] = dict(option)
        trial = replace(cell, planning=replace(cell.planning, **settings))
        if why == Cause.BEND:
            left = len(bends(directions(toolpath, trial).toolpath, trial).waypoint)
            if left:
                tried.append(f"{_text(option)}: {left} waypoints still bent")
                continue
        try:
            result = plan(toolpath, trial)
        except Refused as exc:
            tried.append(f"{_text(option)}: refused ({exc.cause})")
            continue
        except InputError as exc:
            tried.append(f"{_text(option)}: {exc.problem.split(':')[0]}")
            continue
        if result.status == PlanStatus.OK:
            return Retry(option, (*tried, f"{_text(option)}: ok"))
        tried.append(f"{_text(option)}: {result.status}")
    return Retry(None, tuple(tried))


def as_cell(user: dict[str, Any], option: dict[str, float]) -> dict[str, Any]:
    """The user's cell overrides (TOML data, empty for the default cell) with ``option`` set
    in ``[planning]``: the file the fix tells the user to plan with."""
    planning = {**user.get("planning", {}), **option}
    return {**user, "planning": planning}
