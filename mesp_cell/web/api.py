"""The console's HTTP and WebSocket API (FastAPI), over the job store and the cell bus.

Answers: 200/201 with JSON; 400 bad input (one line), 401 without the token where it is
needed, 404 unknown job or file, 409 an invalid transition (the supervisor's or the store's
reason), 413 an upload too large, 422 malformed requests (FastAPI's validation), 503 when the
cell does not answer. Every error body is ``{"detail": "<problem>; <fix>"}``; nothing answers
with a traceback. The OpenAPI description is at ``/openapi.json``.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

from fastapi import Depends, FastAPI, File, Form, Request, UploadFile, WebSocket
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, RedirectResponse
from fastapi.staticfiles import StaticFiles
from starlette.websockets import WebSocketDisconnect

from mesp_cell.bus.session import Bus
from mesp_cell.estop_check import confirm_estop
from mesp_cell.jobs import FINAL, JobRecord, JobStore
from mesp_cell.messages import Command, EStop
from mesp_cell.web.live import LiveState
from mesp_cell.web.preview import toolpath_preview
from mesp_cell.web.token import bearer_ok
from mesp_cell.web.uploads import TooLarge, store_upload
from slicer.errors import InputError

log = logging.getLogger("mesp.console")
STATIC = Path(__file__).resolve().parent / "static"
LIVE_PERIOD_S = 0.2  # the stream's period without news (the supervisor publishes at 5 Hz)


class ApiError(Exception):
    """An answer other than 2xx, with its one-line reason."""

    def __init__(self, status: int, detail: str) -> None:
        super().__init__(detail)
        self.status, self.detail = status, detail


@dataclass
class ConsoleContext:
    """What the API serves from. ``token`` "" = none configured; ``token_all``: every call
    needs it (the console is bound beyond loopback)."""

    cell: str
    home: Path
    db_path: Path
    bus: Bus
    live: LiveState
    token: str = ""
    token_all: bool = False
    max_upload: int = 64 << 20
    clients: set[asyncio.Queue[dict[str, Any]]] = field(default_factory=set)
    loop: asyncio.AbstractEventLoop | None = None  # the server's, once it runs
    news: asyncio.Event | None = None  # set (thread-safe) when a progress message arrives
    _local: threading.local = field(default_factory=threading.local)

    @property
    def store(self) -> JobStore:
        """This thread's connection to the job store (one SQLite connection per thread: the
        API's handlers run on a thread pool)."""
        store = getattr(self._local, "store", None)
        if store is None:
            store = self._local.store = JobStore(self.db_path)
        return store


def job_json(job: JobRecord, history: list[tuple[float, str, str, str]] | None = None
             ) -> dict[str, Any]:
    """A job as the API shows it; with its ``history``, also the duration and result."""
    out: dict[str, Any] = {
        "id": job.id, "state": job.state, "reason": job.reason, "model": Path(job.model).name,
        "created": job.created, "updated": job.updated, "layer": job.layer,
        "layers": job.layers, "waypoint": job.waypoint, "waypoints": job.waypoints,
        "percent": job.percent, "eta_s": job.eta_s if job.state == "printing" else None,
        "ink_mm3": job.volume, "resume_pending": bool(job.resume),
        "ready_confirmed": bool(job.ready), "final": job.state in FINAL}
    if history is not None:
        starts = [t for t, _, new, _ in history if new == "printing"]
        out["started"] = starts[0] if starts else None
        out["duration_s"] = (job.updated - starts[0]) if starts and job.state in FINAL else None
        out["result"] = job.state if job.state in FINAL else None
        out["history"] = [{"t": t, "from": a, "to": b, "reason": r} for t, a, b, r in history]
    return out


def figure_files(job_dir: Path) -> dict[str, Path]:
    """The job's PNG figures by name (the job directory and its ``figures/``)."""
    return {p.name: p for p in (*job_dir.glob("*.png"), *(job_dir / "figures").glob("*.png"))}


def build_app(ctx: ConsoleContext) -> FastAPI:
    """The console's ASGI application."""
    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        ctx.loop, ctx.news = asyncio.get_running_loop(), asyncio.Event()
        task = asyncio.create_task(broadcaster(ctx, ctx.news))
        yield
        task.cancel()

    app = FastAPI(title="MESP Cell console", version="1", docs_url=None, redoc_url=None,
                  description=__doc__, lifespan=lifespan)

    @app.exception_handler(ApiError)
    async def api_error(request: Request, exc: ApiError) -> JSONResponse:
        headers = {"WWW-Authenticate": "Bearer"} if exc.status == 401 else None
        return JSONResponse({"detail": exc.detail}, exc.status, headers=headers)

    @app.exception_handler(RequestValidationError)
    async def bad_request(request: Request, exc: RequestValidationError) -> JSONResponse:
        errs = exc.errors()
        first = errs[0] if errs else {}
        where = ".".join(str(p) for p in first.get("loc", ()))
        return JSONResponse({"detail": f"{where}: {first.get('msg', 'invalid')}; see "
                                       "/openapi.json"}, 422)

    @app.exception_handler(Exception)
    async def any_error(request: Request, exc: Exception) -> JSONResponse:
        return JSONResponse({"detail": f"console error {type(exc).__name__}: {exc}; see the "
                                       "console's log"}, 503)

    def auth(request: Request) -> None:
        if ctx.token_all and not bearer_ok(ctx.token, request.headers.get("authorization")):
            raise ApiError(401, "a bearer token is required; send 'Authorization: Bearer "
                                "<token>' (the token is in $MESP_HOME/console/token)")

    def auth_motion(request: Request) -> None:
        if ctx.token and not bearer_ok(ctx.token, request.headers.get("authorization")):
            raise ApiError(401, "this action needs the console's bearer token; send "
                                "'Authorization: Bearer <token>' ($MESP_HOME/console/token)")

    read = [Depends(auth)]
    act = [Depends(auth_motion)]

    def job_of(job_id: str) -> JobRecord:
        try:
            job = ctx.store.get(job_id)
        except InputError as exc:
            raise ApiError(404, exc.one_line()) from exc
        if job.cell != ctx.cell:
            raise ApiError(404, f"job {job_id} belongs to cell '{job.cell}'; ask that cell")
        return job

    def request(node: str, cmd: Command, timeout: float = 5.0) -> dict[str, Any]:
        reply = ctx.bus.request(node, cmd, timeout)
        if not reply.ok:
            if reply.reason.startswith("no reply from node"):
                raise ApiError(503, f"{reply.reason}; check `mesp launch` and its logs")
            raise ApiError(409, reply.reason)
        return {"ok": True}

    # -- page ------------------------------------------------------------------------------
    @app.get("/", include_in_schema=False)
    def index() -> RedirectResponse:
        return RedirectResponse("/static/index.html")

    app.mount("/static", StaticFiles(directory=STATIC), name="static")

    @app.get("/vendor/plotly.min.js", include_in_schema=False)
    def plotly_js() -> FileResponse:
        import plotly

        path = Path(plotly.__file__).parent / "package_data" / "plotly.min.js"
        return FileResponse(path, media_type="text/javascript",
                            headers={"Cache-Control": "max-age=86400"})

    # -- cell ------------------------------------------------------------------------------
    @app.get("/api/cell", dependencies=read, summary="cell state and nodes alive")
    def cell_state() -> dict[str, Any]:
        snap = ctx.live.snapshot(lambda j: None)
        reply = ctx.bus.request("robot", Command.make("status"), 1.0)
        estop = str(reply.value("estopped", "")) if reply.ok else ""
        if not estop and snap.get("extruder", {}).get("estop"):
            estop = "extruder e-stop latched"
        return {"cell": ctx.cell, "alive": snap["alive"], "estop": estop,
                "robot": snap.get("robot"), "extruder": snap.get("extruder"),
                "token_required": "all" if ctx.token_all else ("motion" if ctx.token else "")}

    @app.post("/api/estop", dependencies=act, summary="software e-stop: robot and extruder")
    def estop(reason: Annotated[str, Form(max_length=200)] = "console") -> dict[str, Any]:
        printing = tuple(j.id for j in ctx.store.query(ctx.cell, ("printing",)))
        sent = time.time()
        ctx.bus.publish_to("estop", "estop", EStop("console", reason, sent))
        done = confirm_estop(ctx.bus, ctx.store, ctx.cell, sent, printing)
        return {"confirmed": done.confirmed, "sent_t": done.sent_t, "robot": done.robot,
                "robot_t": done.robot_t, "extruder": done.extruder,
                "extruder_t": done.extruder_t, "jobs": dict(done.jobs), "lines": done.lines()}

    @app.post("/api/estop/reset", dependencies=act, summary="clear a latched e-stop")
    def estop_reset() -> dict[str, Any]:
        bad = [n for n in ("robot", "extruder")
               if not ctx.bus.request(n, Command.make("reset"), 3.0).ok]
        if bad:
            raise ApiError(503, f"{', '.join(bad)} did not confirm the reset; check that the "
                                "cell is running")
        return {"ok": True}

    @app.get("/api/calibration", dependencies=read, summary="extrusion profiles on this cell")
    def calibration() -> dict[str, Any]:
        from slicer.configtools import read_toml

        out = []
        roots = [ctx.home / "profiles", Path(__file__).resolve().parents[2] / "slicer"
                 / "profiles"]
        for root in roots:
            for path in sorted(root.glob("*.toml")) if root.is_dir() else []:
                try:
                    data = read_toml(path)
                except InputError:
                    continue
                out.append({"name": path.stem, "file": str(path),
                            "calibration": data.get("calibration"),
                            "density_g_cm3": data.get("density_g_cm3")})
        return {"profiles": out}

    # -- jobs ------------------------------------------------------------------------------
    @app.get("/api/jobs", dependencies=read, summary="the queue and recent jobs, oldest first")
    def jobs(all: bool = True) -> list[dict[str, Any]]:
        rows = ctx.store.query(ctx.cell)
        return [job_json(j) for j in rows if all or j.state not in FINAL]

    @app.post("/api/jobs", dependencies=act, status_code=201,
              summary="upload a model (and a job TOML) and queue it")
    def submit(model: Annotated[UploadFile, File()],
               job: Annotated[UploadFile | None, File()] = None) -> dict[str, Any]:
        try:
            path, job_path = store_upload(ctx.home / "jobs", model.file, model.filename,
                                          job.file if job is not None else None,
                                          ctx.max_upload)
        except TooLarge as exc:
            raise ApiError(413, exc.one_line()) from exc
        except InputError as exc:
            raise ApiError(400, exc.one_line()) from exc
        rec = ctx.store.submit(path, ctx.cell, ctx.home / "jobs", job_path)
        return job_json(rec, ctx.store.history(rec.id))

    @app.get("/api/jobs/{job_id}", dependencies=read, summary="a job with its history")
    def job_status(job_id: str) -> dict[str, Any]:
        job = job_of(job_id)
        return job_json(job, ctx.store.history(job.id))

    @app.get("/api/history", dependencies=read,
             summary="finished jobs: duration, ink and result, newest first")
    def history() -> list[dict[str, Any]]:
        done = [j for j in ctx.store.query(ctx.cell) if j.state in FINAL]
        return [job_json(j, ctx.store.history(j.id)) for j in reversed(done)]

    def control(verb: str) -> Callable[[str], dict[str, Any]]:
        def handler(job_id: str) -> dict[str, Any]:
            job = job_of(job_id)
            args = {"who": "the console operator"} if verb == "ready" else {}
            request("supervisor", Command.make(verb, job.id, **args))
            return job_json(ctx.store.get(job.id))
        return handler

    for verb, text in (("pause", "pause a printing job"),
                       ("resume", "resume a paused or interrupted job"),
                       ("abort", "abort a job; a printing one retracts and goes home"),
                       ("ready", "confirm the tank is ready for the job in ready_check")):
        app.post(f"/api/jobs/{{job_id}}/{verb}", dependencies=act, summary=text,
                 name=verb)(control(verb))

    @app.get("/api/jobs/{job_id}/preview", dependencies=read,
             summary="the toolpath's layers as polylines (x, y, z, layer, width, speed)")
    def preview(job_id: str) -> dict[str, Any]:
        job = job_of(job_id)
        try:
            return toolpath_preview(Path(job.dir))
        except InputError as exc:
            raise ApiError(409, exc.one_line()) from exc

    @app.get("/api/jobs/{job_id}/figures", dependencies=read, summary="the job's figures")
    def figures(job_id: str) -> list[str]:
        return sorted(figure_files(Path(job_of(job_id).dir)))

    @app.get("/api/jobs/{job_id}/figures/{name}", dependencies=read, summary="one figure")
    def figure(job_id: str, name: str) -> FileResponse:
        job = job_of(job_id)
        known = figure_files(Path(job.dir))
        if name not in known:  # only a name the listing gave, never a client's path
            raise ApiError(404, f"job {job.id} has no figure '{name}'; see its figure list")
        return FileResponse(known[name], media_type="image/png")

    # -- live stream -----------------------------------------------------------------------
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

    return app


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
