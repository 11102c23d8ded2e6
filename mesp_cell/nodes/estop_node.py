"""The e-stop node: the cell's resident e-stop path.

It is on the bus from the cell's start, so an e-stop costs one publish instead of a zenoh
start-up. It listens on a Unix socket (``socket``, mode 0600; ``estop_socket``): a line (the
reason, or ``{"reason": ...}``) publishes an ``EStop`` on ``estop/estop`` at once (the robot
node stops its stream in one servo period and the screw with it; the extruder node stops the
motor and latches the e-stop), then the node waits for the nodes to confirm (``estop_check``)
and answers one JSON line: when it was sent, what stopped and when, and whether every node
confirmed.
Parameters: socket (path), jobs_db (the job store: which jobs were printing).
"""

from __future__ import annotations

import json
import logging
import os
import socket
import time
from collections.abc import Sequence
from pathlib import Path

from core.status import JobState
from mesp_cell.estop_check import confirm_estop
from mesp_cell.jobs import JobStore
from mesp_cell.messages import EStop
from mesp_cell.nodes.lifecycle import LifecycleNode, NodeStartError, node_main

log = logging.getLogger("mesp.estop")


class EStopNode(LifecycleNode):
    """See the module docstring."""

    def on_configure(self) -> None:
        self.path = Path(self.params["socket"])
        self.store = JobStore(Path(self.params["jobs_db"]))
        try:
            self.path.unlink(missing_ok=True)
            self.server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            old = os.umask(0o177)
            try:
                self.server.bind(str(self.path))
            finally:
                os.umask(old)
            self.server.listen(8)
            self.server.settimeout(0.2)
        except OSError as exc:
            raise NodeStartError(f"cannot listen on {self.path}: {exc}",
                                 "check that the cell's run folder is writable") from exc

    def on_activate(self) -> None:
        self.spawn(self._serve, "listen")

    def on_shutdown(self) -> None:
        self.server.close()
        self.path.unlink(missing_ok=True)
        self.store.close()

    def _serve(self) -> None:
        while not self.stopping.is_set():
            try:
                conn, _ = self.server.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            with conn:
                try:
                    self._answer(conn)
                except (OSError, ValueError) as exc:
                    log.warning("e-stop request failed: %s", exc)

    def _answer(self, conn: socket.socket) -> None:
        conn.settimeout(1.0)
        data = b""
        while not data.endswith(b"\n"):
            chunk = conn.recv(4096)
            if not chunk:
                break
            data += chunk
        line = data.decode(errors="replace").strip()
        # the reason as plain text (``estop_socket.request_line``); a JSON object's "reason"
        # (a wired button's ``echo '{}' | nc -U``); empty: the operator's
        reason = (str(json.loads(line).get("reason", "operator")) if line.startswith("{")
                  else line) or "operator"
        reason = reason[:200]
        assert self.bus is not None
        sent = time.time()
        self.bus.publish("estop", EStop("operator (mesp estop)", reason, sent))
        log.warning("e-stop sent: %s", reason)
        # the jobs it stopped: printing, or interrupted since (the store is read after the
        # publish, which waits for nothing)
        printing = tuple(j.id for j in self.store.query(self.bus_config.cell,
                                                        ("printing", "interrupted"))
                         if j.state == JobState.PRINTING or j.updated >= sent)
        done = confirm_estop(self.bus, self.store, self.bus_config.cell, sent, printing)
        conn.sendall(json.dumps({"sent_t": sent, "lines": done.lines(),
                                 "confirmed": done.confirmed}).encode() + b"\n")


def main(argv: Sequence[str] | None = None) -> int:
    """Process entry point."""
    return node_main(EStopNode, argv, "estop")


if __name__ == "__main__":
    raise SystemExit(main())
