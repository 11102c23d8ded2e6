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
import time
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Annotated, Any

from fastapi import Depends, FastAPI, File, Form, Request, UploadFile
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, RedirectResponse, Response
from fastapi.staticfiles import StaticFiles

from core.errors import InputError
from core.status import JobState
from mesp_cell.estop_check import confirm_estop
from mesp_cell.jobs import FINAL, JobRecord
from mesp_cell.messages import Command, EStop
from mesp_cell.web.context import ApiError, ConsoleContext, figure_files, job_json
from mesp_cell.web.preview import toolpath_preview
from mesp_cell.web.stream import add_live_route, broadcaster
from mesp_cell.web.token import bearer_ok
from mesp_cell.web.uploads import TooLarge, store_upload

STATIC = Path(__file__).resolve().parent / "static"


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
        printing = tuple(j.id for j in ctx.store.query(ctx.cell, (JobState.PRINTING,)))
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

    @app.get("/api/twin.png", dependencies=read, response_class=Response,
             summary="the twin drawn at the pose the robot reports (PNG, at most 1 new frame/s)")
    def twin_png() -> Response:
        if ctx.twin is None:
            raise ApiError(404, "this console draws no twin (its node has no twin view)")
        robot = ctx.live.robot
        if robot is None:
            raise ApiError(503, "no robot state on the bus yet; is the robot node running "
                                "(`mesp node list`)?")
        png, why = ctx.twin.frame(robot.q)
        if png is None:
            raise ApiError(503, why)
        return Response(png, media_type="image/png", headers={"Cache-Control": "no-store"})

    @app.get("/api/calibration", dependencies=read, summary="extrusion profiles on this cell")
    def calibration() -> dict[str, Any]:
        from core.configtools import read_toml

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
        rec = ctx.store.submit(path, ctx.cell, job_path)
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

    add_live_route(app, ctx)
    return app
