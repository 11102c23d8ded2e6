"""The one exception type for a user's mistake.

Solvers return a status and a trace; only bad input raises. The CLI turns an
``InputError`` into a single line ``error: <problem>; <fix>`` and a non-zero exit.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad input from a user: a file, a config value, a placement.

    Attributes:
        problem: what is wrong, naming the offending thing.
        fix: what the user can do about it.
    """

    def __init__(self, problem: str, fix: str = "") -> None:
        self.problem = problem.strip().rstrip(".")
        self.fix = fix.strip().rstrip(".")
        super().__init__(self.one_line())

    def one_line(self) -> str:
        """The message as a single line: problem, then fix."""
        text = self.problem if not self.fix else f"{self.problem}; {self.fix}"
        return " ".join(text.split())
