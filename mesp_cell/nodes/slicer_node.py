"""The slicer node: ``slice`` (args model, job_file, dir) runs the slicing pipeline for a job.

Artifacts stay in the job directory; the reply carries the toolpath's path and sha256, never
the arrays. Parameter ``slice_fn`` ("module:function") replaces the pipeline (tests).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from mesp_cell.drivers.stream import sha256_of
from mesp_cell.messages import Command, Reply
from mesp_cell.nodes import adapters
from mesp_cell.nodes.lifecycle import LifecycleNode, node_main


class SlicerNode(LifecycleNode):
    """See the module docstring."""

    def on_configure(self) -> None:
        spec = self.params.get("slice_fn")
        self.fn = adapters.resolve(spec) if spec else adapters.slice_job

    def on_activate(self) -> None:
        self.serve(self._on_command)

    def _on_command(self, cmd: Command) -> Reply:
        if cmd.verb != "slice":
            return Reply.refuse(f"unknown slicer command '{cmd.verb}'")
        # Commands arrive one at a time on the bus worker thread: one job at a time.
        out = Path(cmd.arg("dir"))
        job_file = cmd.arg("job_file") or None
        cell_file = cmd.arg("cell_file") or None
        self.fn(Path(cmd.arg("model")), Path(job_file) if job_file else None, out,
                self.bus_config.cell, Path(cell_file) if cell_file else None)
        path = out / "toolpath.npz"
        if not path.is_file():
            return Reply.refuse(f"slicing wrote no {path}")
        return Reply.done(path=str(path), sha256=sha256_of(path))


def main(argv: Sequence[str] | None = None) -> int:
    """Process entry point."""
    return node_main(SlicerNode, argv, "slicer")


if __name__ == "__main__":
    raise SystemExit(main())
