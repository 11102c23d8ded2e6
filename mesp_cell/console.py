"""Terminal progress display for the `mesp` commands (stderr, so stdout stays parseable).

Drawn with ``rich``: on a terminal a live bar for the running stage, which gives way to one
line per finished stage; to a pipe or file only those lines, without control codes.
"""

from __future__ import annotations

import sys
from typing import IO

from rich.console import Console
from rich.progress import BarColumn, Progress, TaskID, TextColumn, TimeElapsedColumn


class ConsoleProgress:
    """Prints one line per finished stage and a live bar for long stages on a TTY."""

    def __init__(self, stream: IO[str] | None = None, quiet: bool = False) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.quiet = quiet
        self.live = bool(getattr(self.stream, "isatty", lambda: False)())
        self.console = Console(file=self.stream, highlight=False, soft_wrap=True,
                               force_terminal=self.live or None)
        self._bar: Progress | None = None
        self._task: TaskID | None = None

    def start(self, stage: str) -> None:
        self._stop_bar()
        if self.quiet or not self.live:
            return
        self._bar = Progress(TextColumn("  {task.description:<16}"), BarColumn(bar_width=24),
                             TextColumn("{task.percentage:5.1f}% {task.fields[detail]}"),
                             TimeElapsedColumn(), console=self.console, transient=True)
        self._task = self._bar.add_task(stage, total=1.0, detail="")
        self._bar.start()

    def update(self, fraction: float, detail: str = "") -> None:
        if self._bar is not None and self._task is not None:
            self._bar.update(self._task, completed=min(max(fraction, 0.0), 1.0), detail=detail)

    def end(self, stage: str, seconds: float) -> None:
        self._stop_bar()
        if not self.quiet:
            self.console.print(f"  {stage:<16} done in {seconds:7.2f} s", markup=False)

    def info(self, text: str) -> None:
        """A line of information for the operator."""
        if not self.quiet:
            self._stop_bar()
            self.console.print(text, markup=False)

    def _stop_bar(self) -> None:
        if self._bar is not None:
            self._bar.stop()
            self._bar = None
            self._task = None
