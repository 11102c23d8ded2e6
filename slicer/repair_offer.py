"""The refusal of an open or non-manifold surface, with ``--repair`` offered only where it was
tried and works.

``mesp slice`` refuses a surface that does not bound a solid; where its reason has a repair
(``slicer.repair``), the repair is tried before the refusal is said: a fill, a split and
join or a stored wrap runs at once, a wrap to make runs in a child process given a few
seconds (fTetWild's time grows with the input's faces, and it holds the interpreter while it
runs, so only a process can be stopped). The fix then says ``re-run with --repair`` and
what it changes, or what ``--repair`` did and why that is still refused, or that it was not
checked in time. The child stores its wrap (``slicer.wrap_cache``), so the ``--repair`` run
that follows, or ``mesp check``, uses that very wrap. What a repair that did not help tried
is read from the refusal's typed field (``RepairRefused.tried``), not parsed from its words.
"""

from __future__ import annotations

import multiprocessing
import queue as queue_module
import time
from pathlib import Path
from typing import Any

import numpy as np

from core.errors import InputError
from slicer.config import ModelConfig
from slicer.mesh_io import Surface
from slicer.repair import WrapNotStored, load_repaired, repairable
from slicer.surface_refusal import RepairRefused, SurfaceReason, SurfaceRefused

# Seconds `mesp slice`'s refusal waits for the check that --repair works.
OFFER_SECONDS = 30.0
_POLL_SECONDS = 0.2


def repair_within(path: str | Path, units: str | ModelConfig, seconds: float,
                  reason: SurfaceReason | None = None) -> Surface | InputError | None:
    """What ``load_repaired`` gives (the surface, or its refusal), None where it takes
    over ``seconds``. A stored wrap is read here; a wrap to make runs in a child process
    (killed after ``seconds``), which stores it for the runs that follow. ``reason``: the
    reason the file was refused for, where known."""
    try:
        return load_repaired(path, units, wrap=False, reason=reason)
    except WrapNotStored:
        pass
    except InputError as exc:
        return exc
    context = multiprocessing.get_context("spawn")  # fork would inherit fTetWild's threads
    queue = context.Queue()
    child = context.Process(target=_repair_child, args=(Path(path), units, reason, queue),
                            daemon=True)
    child.start()
    deadline = time.monotonic() + seconds
    answer: tuple[Any, ...] | None = None
    try:
        while answer is None and time.monotonic() < deadline:
            try:
                answer = queue.get(timeout=_POLL_SECONDS)
            except queue_module.Empty:
                if not child.is_alive() and queue.empty():
                    answer = ("refused", f"{Path(path).name}: the --repair check ended "
                              f"without an answer (exit code {child.exitcode})",
                              "slice with --repair to see its error")
    finally:
        if child.is_alive():
            child.kill()
        child.join()
    if answer is None:
        return None
    if answer[0] == "refused":
        return _refusal(*answer[1:])
    _, vertices, faces, notes = answer
    return Surface(vertices=vertices, faces=faces, source=Path(path), notes=notes)


def _repair_child(path: Path, units: str | ModelConfig, reason: SurfaceReason | None,
                  queue: Any) -> None:
    """Child process: ``load_repaired``'s surface (arrays and notes) or its refusal (as
    ``_refusal``'s arguments: an exception's own attributes do not survive the queue)."""
    try:
        surface = load_repaired(path, units, reason=reason)
    except RepairRefused as exc:
        queue.put(("refused", exc.problem, exc.fix, exc.name, exc.tried))
    except InputError as exc:
        queue.put(("refused", exc.problem, exc.fix))
    else:
        queue.put(("ok", np.asarray(surface.vertices), np.asarray(surface.faces),
                   surface.notes))


def repair_offer(path: str | Path, units: str | ModelConfig, refusal: InputError,
                 seconds: float = OFFER_SECONDS) -> InputError:
    """The refusal with ``--repair`` as its fix where the repair was tried here and works,
    its fix and that ``--repair`` was tried and does not help where it does not, and that
    it was not checked where it takes over ``seconds``. ``refusal`` unchanged where no
    repair answers its reason."""
    if not isinstance(refusal, SurfaceRefused) or not repairable(refusal):
        return refusal
    fix = offer_fix(refusal, repair_within(path, units, seconds, refusal.reason), seconds)
    return SurfaceRefused(refusal.problem, fix, refusal.reason)


def offer_fix(refusal: InputError, outcome: Surface | InputError | None, seconds: float,
              use: str = "re-run with --repair") -> str:
    """The fix of ``refusal`` given ``repair_within``'s ``outcome`` within ``seconds``:
    ``use`` --repair (checked, what it changes), or the refusal's fix and that --repair was
    tried and does not help, or was not checked in time."""
    if outcome is None:
        return (f"{refusal.fix}; or {use} (fTetWild's wrap: not checked here, it takes "
                f"over {seconds:.0f} s on this mesh)")
    if isinstance(outcome, InputError):
        return f"{refusal.fix} (--repair was tried: {_tried(outcome)})"
    return f"{use} (checked: it {outcome.notes[0].removeprefix('--repair: ')})"


def _refusal(problem: str, fix: str, name: str | None = None,
             tried: str | None = None) -> InputError:
    """The refusal the child sent: a ``RepairRefused`` where it was one (``name`` and
    ``tried`` given), else an ``InputError``."""
    if name is not None and tried is not None:
        return RepairRefused(name, tried, fix)
    return InputError(problem, fix)


def _tried(refused: InputError) -> str:
    """``load_repaired``'s refusal, short: what ``--repair`` did and why the result is
    refused (``RepairRefused.tried``); any other refusal whole."""
    return refused.tried if isinstance(refused, RepairRefused) else refused.problem
