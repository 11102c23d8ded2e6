"""The console node: serves the operator's web page and the HTTP/WebSocket API of the cell.

A node like the others (its own process, declared in the launch files): it follows the
supervisor's progress and the robot's and extruder's states on the bus, reads and writes the
job store, and sends the supervisor its commands. uvicorn runs in a thread of the node; the
node declares its liveliness token once the server accepts connections. Parameters:
``host`` (127.0.0.1), ``port`` (8765), ``jobs_db``, ``max_upload_mb`` (64), ``dt`` (0.002).
Binding beyond loopback creates the bearer token (``$MESP_HOME/console/token``, 0600) and
requires it for every call; on loopback an existing token guards the actions that move or
stop the cell.
"""

from __future__ import annotations

import logging
import os
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from mesp_cell.bus.signing import Role
from mesp_cell.messages import ExtruderState, JobProgress, RobotState
from mesp_cell.nodes.lifecycle import LifecycleNode, NodeStartError, node_main
from mesp_cell.web.live import LiveState
from mesp_cell.web.token import is_loopback, load_token, token_path

log = logging.getLogger("mesp.console")


def console_url(host: str, port: int) -> str:
    """The page's address for a bind address (0.0.0.0 is shown as this host's name)."""
    shown = host
    if host in ("0.0.0.0", "::"):
        import socket

        shown = socket.gethostname()
    if ":" in shown:
        shown = f"[{shown}]"
    return f"http://{shown}:{port}/"


def console_urls(processes: Sequence[Any]) -> list[str]:
    """The console pages of a launch description's processes (``ProcessSpec``s)."""
    return [console_url(str(p.params.get("host", "127.0.0.1")), int(p.params.get("port", 8765)))
            for p in processes if p.module == "mesp_cell.web.node" and p.params]


class ConsoleNode(LifecycleNode):
    """See the module docstring."""

    bus_role = Role.OPERATOR  # it passes on the operator's commands

    def on_configure(self) -> None:
        import uvicorn

        from mesp_cell.web.api import build_app
        from mesp_cell.web.context import ConsoleContext
        from mesp_cell.web.twin_view import TwinView

        p = self.params
        self.host = str(p.get("host", "127.0.0.1"))
        try:
            self.port = int(p.get("port", 8765))
            max_mb = float(p.get("max_upload_mb", 64))
        except (TypeError, ValueError) as exc:
            raise NodeStartError(f"bad console parameters: {exc}",
                                 "give port and max_upload_mb as numbers") from exc
        home = Path(os.environ.get("MESP_HOME") or Path.home() / ".mesp")
        remote = not is_loopback(self.host)
        # made at the first start wherever it binds: on loopback too, another user of the
        # host must not act as the operator through the console (docs/security.md)
        token = load_token(home, create=True)
        if remote:
            log.info("console bound to %s: every call needs the bearer token in %s",
                     self.host, token_path(home))
        else:
            log.info("console: the motion and e-stop endpoints need the bearer token in %s",
                     token_path(home))
        assert self.bus is not None
        self.live = LiveState(float(p.get("dt", 0.002)))
        cell_file = str(p.get("cell_file", "") or "")
        self.ctx = ConsoleContext(cell=self.bus_config.cell, home=home,
                                  db_path=Path(p.get("jobs_db", home / "jobs.sqlite")),
                                  bus=self.bus, live=self.live, token=token, token_all=remote,
                                  max_upload=int(max_mb * (1 << 20)),
                                  twin=TwinView(Path(cell_file) if cell_file else None))
        app = build_app(self.ctx)
        config = uvicorn.Config(app, host=self.host, port=self.port, log_level="warning",
                                ws="websockets-sansio", lifespan="on")
        self.server = uvicorn.Server(config)
        self._thread: threading.Thread | None = None

    def _on_progress(self, msg: JobProgress) -> None:
        self.live.on_progress(msg)
        loop, news = self.ctx.loop, self.ctx.news
        if loop is not None and news is not None:
            loop.call_soon_threadsafe(news.set)  # send it now, not at the next period

    def on_activate(self) -> None:
        assert self.bus is not None
        self.bus.subscribe("supervisor", "progress", JobProgress, self._on_progress)
        self.bus.subscribe("robot", "state", RobotState, self.live.on_robot)
        self.bus.subscribe("extruder", "state", ExtruderState, self.live.on_extruder)
        self.bus.watch_presence(self.live.on_presence)
        self._thread = self.spawn(self.server.run, "http")
        while not self.server.started:
            if not self._thread.is_alive():
                raise NodeStartError(f"the console cannot listen on {self.host}:{self.port}",
                                     "free the port or set another one (--set "
                                     "console_port=...)")
            self.stopping.wait(0.02)
        log.info("console at %s", console_url(self.host, self.port))

    def on_deactivate(self) -> None:
        self.server.should_exit = True

    def on_shutdown(self) -> None:
        if self._thread is not None:
            self._thread.join(3.0)
        if self.ctx.twin is not None:
            self.ctx.twin.close()


def main(argv: Sequence[str] | None = None) -> int:
    """Process entry point."""
    from sim.gl import choose_gl

    choose_gl()  # the twin view's offscreen GL, before mujoco is first imported
    return node_main(ConsoleNode, argv, "console")


if __name__ == "__main__":
    raise SystemExit(main())
