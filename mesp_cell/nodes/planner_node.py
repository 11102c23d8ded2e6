"""The planner node: ``plan`` (args dir, cell_file) plans a sliced job into trajectory.npz.

The reply carries the trajectory's path and sha256. A plan that cannot reach the job is a
refusal with the planner's one-line reason. Parameter ``plan_fn`` replaces the planner (tests).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from mesp_cell.drivers.stream import sha256_of
from mesp_cell.messages import Command, Reply
from mesp_cell.nodes import adapters
from mesp_cell.nodes.lifecycle import LifecycleNode, node_main


class PlannerNode(LifecycleNode):
    """See the module docstring."""

    def on_configure(self) -> None:
        spec = self.params.get("plan_fn")
        self.fn = adapters.resolve(spec) if spec else adapters.plan_job

    def on_activate(self) -> None:
        self.serve(self._on_command)

    def _on_command(self, cmd: Command) -> Reply:
        if cmd.verb != "plan":
            return Reply.refuse(f"unknown planner command '{cmd.verb}'")
        # Commands arrive one at a time on the bus worker thread: one job at a time.
        job_dir = Path(cmd.arg("dir"))
        cell_file = cmd.arg("cell_file") or None
        self.fn(job_dir, Path(cell_file) if cell_file else None)
        path = job_dir / "trajectory.npz"
        if not path.is_file():
            return Reply.refuse(f"planning wrote no {path}")
        return Reply.done(path=str(path), sha256=sha256_of(path))


def main(argv: Sequence[str] | None = None) -> int:
    """Process entry point."""
    return node_main(PlannerNode, argv, "planner")


if __name__ == "__main__":
    raise SystemExit(main())
