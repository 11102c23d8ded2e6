"""Progress reporting for long work, without tying libraries to a console.

Libraries take a ``Progress`` and call ``stage(name)`` around each stage and ``update`` inside
long loops; the CLI passes one that draws, tests pass ``NullProgress``.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Protocol


class Progress(Protocol):
    """Receives stage starts and ends, and fractional progress inside a stage."""

    def start(self, stage: str) -> None: ...

    def update(self, fraction: float, detail: str = "") -> None: ...

    def end(self, stage: str, seconds: float) -> None: ...


class NullProgress:
    """Reports nothing."""

    def start(self, stage: str) -> None:
        pass

    def update(self, fraction: float, detail: str = "") -> None:
        pass

    def end(self, stage: str, seconds: float) -> None:
        pass


class StageTimer:
    """Times named stages and forwards them to a ``Progress``.

    Attributes:
        seconds: stage name -> wall-clock seconds, in the order the stages ran.
    """

    def __init__(self, progress: Progress | None = None) -> None:
        self.progress: Progress = progress if progress is not None else NullProgress()
        self.seconds: dict[str, float] = {}

    @contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """Time the body as stage ``name`` (accumulates if run twice)."""
        self.progress.start(name)
        start = time.perf_counter()
        yield  # a stage that raises is neither timed nor reported as done
        elapsed = time.perf_counter() - start
        self.seconds[name] = self.seconds.get(name, 0.0) + elapsed
        self.progress.end(name, elapsed)
