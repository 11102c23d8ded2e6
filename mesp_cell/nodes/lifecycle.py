"""The lifecycle every node shares: states, heartbeat, presence, signals.

States follow the managed-node pattern: unconfigured -> (configure) -> inactive -> (activate)
-> active -> (deactivate) -> inactive -> (shutdown) -> finalized. ``configure`` opens the bus
and the devices, ``activate`` starts publishing and serving, ``deactivate`` makes the node's
devices safe (motion and extrusion stop), ``shutdown`` closes everything.

Authority: the node's bus session signs as a cell ``node`` (``bus_role``; the console signs as
the operator). Every command it serves is first checked for its sender
(``command_policy``: the supervisor, the operator, or the node a verb is for) and then for its
arguments (``command_checks``), whichever way the node serves it; a refusal is the reply and
is logged. Presence: the liveliness token goes up with the first signed heartbeat, and other
nodes count this one present only while both come (``mesp_cell.bus.presence``).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from mesp_cell.bus.session import Bus, BusConfig
from mesp_cell.bus.signing import Role, Signer
from mesp_cell.command_policy import sender_refusal
from mesp_cell.messages import Command, Heartbeat, Reply
from mesp_cell.states import NodeState

log = logging.getLogger("mesp")

#: A node that cannot start writes one line starting with this to its log; the launcher
#: shows it (``launcher.start_error``) instead of "see the log".
START_ERROR = "cannot start: "
#: Separates the reason from the fix on that line.
START_FIX = " | fix: "


class NodeStartError(Exception):
    """A node cannot start for a reason outside the program (a device that does not answer,
    a bad parameter): one line for the operator, what is wrong and how to fix it."""

    def __init__(self, reason: str, fix: str) -> None:
        super().__init__(reason)
        self.reason = reason
        self.fix = fix


class LifecycleNode:
    """Base class of a node process. Subclasses override the ``on_*`` hooks."""

    heartbeat_s = 0.5
    bus_role = Role.NODE  # what the node's bus session signs as

    def __init__(self, name: str, bus_config: BusConfig, params: dict[str, Any]) -> None:
        self.name = name
        self.bus_config = bus_config
        self.params = params
        self.state = NodeState.UNCONFIGURED
        self.bus: Bus | None = None
        self.stopping = threading.Event()
        self.failed = ""  # why the node stopped on its own (a worker thread died)
        self._failed_t = 0.0  # s, monotonic, when it failed
        self._seq = 0
        self._threads: list[threading.Thread] = []
        self._workers: list[threading.Thread] = []

    # -- hooks -----------------------------------------------------------------------------
    def on_configure(self) -> None:
        """Open devices (the bus is already open). On failure it closes what it opened and
        raises (``NodeStartError`` for the operator's mistakes); ``on_shutdown`` then does not
        run."""

    def on_activate(self) -> None:
        """Start serving and publishing."""

    def on_deactivate(self) -> None:
        """Make devices safe."""

    def on_shutdown(self) -> None:
        """Release devices."""

    # -- transitions -----------------------------------------------------------------------
    def configure(self) -> None:
        assert self.state == NodeState.UNCONFIGURED
        self.bus = Bus(self.bus_config, self.name, role=self.bus_role)
        self.bus.default_authorize = self.authorize
        self.on_configure()
        self.state = NodeState.INACTIVE

    def activate(self) -> None:
        assert self.state == NodeState.INACTIVE and self.bus is not None
        self.on_activate()
        self.state = NodeState.ACTIVE
        self.bus.presence_warm()  # its view of the others is up before it counts as up
        self._beat()  # presence only once the node can do its job: a signed beat, then the token
        self.bus.announce()
        self.spawn(self._heartbeat, "heartbeat")

    def deactivate(self) -> None:
        """Make devices safe; a failed node too (its devices were active when it failed)."""
        if self.state in (NodeState.ACTIVE, NodeState.FAILED):
            self.state = NodeState.INACTIVE
            self.on_deactivate()

    def shutdown(self) -> None:
        self.deactivate()
        self.stopping.set()
        try:
            if self.state != NodeState.UNCONFIGURED:  # a failed configure released its own devices
                self.on_shutdown()
        finally:
            if self.bus is not None:
                self.bus.close()
            self.state = NodeState.FINALIZED

    # -- helpers ---------------------------------------------------------------------------
    def spawn(self, target: Any, name: str) -> threading.Thread:
        """Start a daemon thread that belongs to this node. An exception that escapes it is
        a bug: the node says so and stops (the launcher restarts it), rather than beating on
        with a dead loop (an extruder whose poll died would look alive and publish nothing)."""

        def guarded() -> None:
            try:
                target()
            except Exception as exc:
                self._node_failed(f"thread {name} crashed: {type(exc).__name__}: {exc}")
                log.exception("%s: thread %s crashed", self.name, name)

        t = threading.Thread(target=guarded, name=f"{self.name}-{name}", daemon=True)
        t.start()
        self._threads.append(t)
        return t

    def serve(self, handler: Callable[[Command], Reply], topic: str = "cmd") -> None:
        """Answer commands on ``topic`` with ``handler`` on the bus's worker thread, which the
        heartbeat then watches. Whatever the handler raises, even a library's ``sys.exit``, is
        a refusal with the reason (the worker lives on); a worker that dies all the same stops
        the node (``_heartbeat``), so the launcher restarts it instead of it looking alive."""
        assert self.bus is not None

        def guarded(cmd: Command) -> Reply:
            try:
                return handler(cmd)
            except SystemExit as exc:  # a library called sys.exit: refuse, never exit
                log.error("command %s on %s: a library exited (%s)", cmd.verb, self.name, exc)
                return Reply.refuse(f"{cmd.verb} failed: a library gave up on the input "
                                    f"(exit {exc.code})")

        before = set(threading.enumerate())
        self.bus.serve(guarded, topic)
        worker = f"{self.bus.node}-{topic}"  # the name Bus.serve gives its worker thread
        self._workers += [t for t in threading.enumerate() if t not in before and t.name == worker]

    def authorize(self, cmd: Command, signer: Signer | None) -> str:
        """'' if this node takes ``cmd`` from ``signer``, else the one-line reason it does not
        (the sender first, then the arguments)."""
        return (sender_refusal(type(self).__name__, cmd, signer, self.params)
                or self.argument_refusal(cmd))

    def argument_refusal(self, cmd: Command) -> str:
        """'' if this node accepts ``cmd``'s arguments, else why not (a node checks what it
        is told itself: ``mesp_cell.command_checks``)."""
        return ""

    def _beat(self) -> None:
        assert self.bus is not None
        self._seq += 1
        self.bus.publish("heartbeat", Heartbeat(self.name, self.state, self._seq, os.getpid(),
                                                time.time()), express=False)

    def _heartbeat(self) -> None:
        while not self.stopping.wait(self.heartbeat_s):
            if self.bus is None:
                return
            dead = [t.name for t in self._workers if not t.is_alive()]
            if dead:  # say so and stop: a node that cannot answer must not look healthy
                self._node_failed(f"worker thread {dead[0]} died")
            self._beat()
            if self.failed:
                self.stopping.set()
                return

    def _node_failed(self, why: str) -> None:
        """Mark the node failed; the heartbeat publishes it and stops the node."""
        if not self.failed:
            self.failed, self._failed_t = why, time.monotonic()
            self.state = NodeState.FAILED
            log.error("%s: %s; stopping so the launcher restarts it", self.name, why)

    def run(self) -> int:
        """Configure, activate, serve until SIGINT/SIGTERM, then deactivate and shut down."""

        def on_signal(signum: int, frame: object) -> None:
            self.stopping.set()

        signal.signal(signal.SIGTERM, on_signal)
        signal.signal(signal.SIGINT, on_signal)
        watch_parent(self.stopping)
        try:
            self.configure()
            self.activate()
            log.info("%s active (pid %d)", self.name, os.getpid())
            while not self.stopping.wait(0.2):
                if self.failed and time.monotonic() - self._failed_t > 2 * self.heartbeat_s + 0.5:
                    break  # the heartbeat that should have stopped the node is gone too
            if self.failed:
                return 1
        except NodeStartError as exc:
            log.error("%s%s%s%s", START_ERROR, exc.reason, START_FIX, exc.fix)
            return 1
        except Exception as exc:
            log.exception("%s%s: %s", START_ERROR, type(exc).__name__, exc)
            return 1
        finally:
            self.shutdown()
            log.info("%s finalized", self.name)
        return 0


def watch_parent(stop: threading.Event) -> None:
    """Set ``stop`` if the launcher that started this process dies (it is reparented).

    Only when started by ``mesp launch`` (``MESP_LAUNCHER_PID`` names the parent), so a crashed
    launcher never leaves devices driven by orphans.
    """
    launcher = int(os.environ.get("MESP_LAUNCHER_PID", "0") or 0)
    if launcher <= 0 or os.getppid() != launcher:
        return

    def watch() -> None:
        while not stop.wait(0.5):
            if os.getppid() != launcher:
                log.error("launcher (pid %d) is gone: shutting down", launcher)
                stop.set()
                return

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def node_main(cls: type[LifecycleNode], argv: Sequence[str] | None, default_name: str) -> int:
    """Shared ``main``: parse ``--name --bus --params`` and run the node."""
    ap = argparse.ArgumentParser(prog=default_name)
    ap.add_argument("--name", default=default_name)
    ap.add_argument("--bus", default=BusConfig().to_json(), help="bus config, JSON")
    ap.add_argument("--params", default="{}", help="node parameters, JSON")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    node = cls(args.name, BusConfig.from_json(args.bus), json.loads(args.params))
    return node.run()
