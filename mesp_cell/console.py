"""Terminal progress display for the `mesp` commands (stderr, so stdout stays parseable)."""

from __future__ import annotations

import sys
import time


class ConsoleProgress:
    """Prints one line per finished stage and a live fraction for long stages on a TTY."""

    def __init__(self, stream=None, quiet: bool = False) -> None:  # type: ignore[no-untyped-def]
        self.stream = stream if stream is not None else sys.stderr
        self.quiet = quiet
        self.live = bool(getattr(self.stream, "isatty", lambda: False)())
        self._stage = ""
        self._last = 0.0

    def start(self, stage: str) -> None:
        self._stage = stage
        if not self.quiet and self.live:
            self.stream.write(f"  {stage} ...\r")
            self.stream.flush()

    def update(self, fraction: float, detail: str = "") -> None:
        now = time.monotonic()
        if self.quiet or not self.live or now - self._last < 0.2:
            return
        self._last = now
        bar = "#" * int(20 * min(max(fraction, 0.0), 1.0))
        line = f"  {self._stage:<16} [{bar:<20}] {100 * fraction:5.1f}% {detail}"
        self.stream.write(line + "\x1b[K\r")
        self.stream.flush()

    def end(self, stage: str, seconds: float) -> None:
        if not self.quiet:
            clear = "\x1b[K" if self.live else ""
            self.stream.write(f"  {stage:<16} done in {seconds:7.2f} s{clear}\n")
            self.stream.flush()

    def info(self, text: str) -> None:
        """A line of information for the operator."""
        if not self.quiet:
            self.stream.write(text + "\n")
            self.stream.flush()
