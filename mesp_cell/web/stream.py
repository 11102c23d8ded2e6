"""The console's live stream: the state the supervisor publishes, joined with the robot's and
the extruder's (``LiveState``), and the queue, to every WebSocket client of ``/api/live``."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from typing import Any

from fastapi import FastAPI, WebSocket
from starlette.websockets import WebSocketDisconnect

from core.errors import InputError
from mesp_cell.jobs import JobRecord
from mesp_cell.web.context import ConsoleContext, job_json
from mesp_cell.web.token import bearer_ok

log = logging.getLogger("mesp.console")
LIVE_PERIOD_S = 0.2  # the stream's period without news (the supervisor publishes at 5 Hz)


def add_live_route(app: FastAPI, ctx: ConsoleContext) -> None:
    """``WS /api/live``: the queue at once, then every message of the broadcaster."""

    @app.websocket("/api/live")
    async def live(ws: WebSocket, token: str = "") -> None:
        if ctx.token_all and not bearer_ok(ctx.token, f"Bearer {token}"):
            await ws.close(code=4401, reason="bearer token required (?token=...)")
            return
        await ws.accept()
        queue: asyncio.Queue[dict[str, Any]] = asyncio.Queue(maxsize=16)
        ctx.clients.add(queue)
        try:
            await ws.send_json(jobs_message(ctx))
            while True:
                msg = await queue.get()
                msg["sent_t"] = time.time()
                await ws.send_json(msg)
        except (WebSocketDisconnect, RuntimeError):
            pass
        finally:
            ctx.clients.discard(queue)


def jobs_message(ctx: ConsoleContext) -> dict[str, Any]:
    """The queue as streamed: every job of the cell, oldest first."""
    return {"type": "jobs", "t": time.time(),
            "jobs": [job_json(j) for j in ctx.store.query(ctx.cell)]}


async def broadcaster(ctx: ConsoleContext, news: asyncio.Event) -> None:
    """Send the live state to every WebSocket client every ``LIVE_PERIOD_S`` and at once when
    a progress message arrives (``news``); the queue whenever a job changes."""
    last_jobs = ""
    last_poll = 0.0

    def job_of(job_id: str) -> JobRecord | None:
        try:
            return ctx.store.get(job_id)
        except InputError:
            return None

    while True:
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(news.wait(), LIVE_PERIOD_S)
        news.clear()
        if not ctx.clients:
            continue
        try:
            msgs = [await asyncio.to_thread(ctx.live.snapshot, job_of)]
            now = time.monotonic()
            if now - last_poll >= 0.25:
                last_poll = now
                jobs = jobs_message(ctx)
                key = repr([(j["id"], j["state"], j["reason"], j["ready_confirmed"],
                             j["resume_pending"], j["layer"], int(j["percent"]))
                            for j in jobs["jobs"]])
                if key != last_jobs:
                    last_jobs = key
                    msgs.append(jobs)
        except Exception:  # the stream must outlive a bad artifact or a busy store
            log.exception("live stream")
            continue
        for q in list(ctx.clients):
            for m in msgs:
                if q.full():
                    with contextlib.suppress(asyncio.QueueEmpty):
                        q.get_nowait()  # a slow client gets the newest state, not a backlog
                q.put_nowait(dict(m))
