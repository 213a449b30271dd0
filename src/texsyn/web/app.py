"""The web application of ``texsyn serve``: the page, the method registry, uploads and jobs.

Endpoints (``docs/web.md``, "API"); every one but ``/static/`` needs the launch's token:

- ``GET /``: the page (``static/index.html``);
- ``GET /api/methods``: every method with its parameter specs (types, ranges, defaults,
  help), the registry the command line reads;
- ``GET /api/exemplars/builtin``: the built-in exemplars; ``POST /api/exemplars``: an upload
  (the raw file as the body, its name in ``X-Filename``); ``GET /api/exemplars/{id}/preview``;
- ``POST /api/jobs``: queue a job (JSON, :func:`texsyn.web.requests.plan_job`);
  ``GET /api/jobs/{id}``: its state; ``GET /api/jobs/{id}/events``: the state as server-sent
  events until it ends; ``POST /api/jobs/{id}/cancel``; ``GET /api/jobs/{id}/files/{key}``.

Refusals are ``{"error": "one line"}`` with a 4xx status, the line as the command line
would print it.
"""

from __future__ import annotations

import asyncio
import json
import shutil
import tempfile
from contextlib import asynccontextmanager
from importlib import resources
from pathlib import Path

from fastapi import FastAPI, Request
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, Response, StreamingResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from .. import data
from .._validation import OneOf, Range
from .._version import __version__
from ..errors import InputError
from ..methods import METHODS
from .jobs import FINAL_STATES, Job, JobManager, QueueFullError
from .requests import plan_job
from .security import RequestGuard, refusal
from .settings import ServerSettings
from .uploads import UploadError, UploadStore

__all__ = ["create_app", "method_catalogue"]

#: largest JSON body of a job request
MAX_JSON_BYTES = 64 * 1024
#: seconds between keep-alive comments of an event stream
KEEP_ALIVE = 15.0


def _allowed(spec) -> dict | None:
    if isinstance(spec.allowed, Range):
        r = spec.allowed
        return {"low": r.low, "high": r.high, "low_open": r.low_open, "high_open": r.high_open}
    if isinstance(spec.allowed, OneOf):
        return {"choices": [str(v) for v in spec.allowed.values]}
    return None


def method_catalogue() -> list[dict]:
    """Every registered method and its parameter specs, as the page builds its form from them."""
    out = []
    for name in sorted(METHODS):
        cls = METHODS[name]
        params = []
        for spec in cls.param_specs().values():
            params.append(
                {
                    "name": spec.name,
                    "type": spec.type.__name__,
                    "default": spec.text(spec.default),
                    "allowed": _allowed(spec),
                    "optional": spec.optional,
                    "help": spec.description,
                    "describe": spec.describe_allowed(),
                }
            )
        out.append(
            {
                "name": name,
                "summary": cls.summary,
                "reference": cls.reference,
                "has_source_map": cls.has_source_map,
                "params": params,
            }
        )
    return out


def _static_text(name: str) -> str:
    return resources.files(__package__).joinpath("static", name).read_text(encoding="utf-8")


def create_app(settings: ServerSettings | None = None, folder: str | Path | None = None):
    """The ASGI application of one server launch.

    Parameters
    ----------
    settings : ServerSettings, optional
    folder : path, optional
        Where uploads and results go; by default a new temporary folder, removed when the
        application stops (nothing is written elsewhere).
    """
    settings = settings or ServerSettings()
    state: dict = {}

    @asynccontextmanager
    async def lifespan(app):
        owned = folder is None
        root = Path(tempfile.mkdtemp(prefix="texsyn-serve-")) if owned else Path(folder)
        state["uploads"] = UploadStore(root / "uploads", settings.max_upload_bytes, settings.max_pixels)
        state["jobs"] = JobManager(
            root / "jobs", settings.workers, settings.queue_limit, settings.job_timeout
        )
        try:
            yield
        finally:
            await state["jobs"].shutdown()
            if owned:
                shutil.rmtree(root, ignore_errors=True)

    app = FastAPI(
        title="texsyn",
        version=__version__,
        lifespan=lifespan,
        docs_url=None,
        redoc_url=None,
        openapi_url=None,
    )

    def uploads() -> UploadStore:
        return state["uploads"]

    def jobs() -> JobManager:
        return state["jobs"]

    def job_or_404(job_id: str) -> Job:
        job = jobs().jobs.get(job_id)
        if job is None:
            raise UploadError("unknown job (jobs last until the server stops)", 404)
        return job

    def token_query(request: Request) -> str:
        return f"?token={settings.token}"

    @app.exception_handler(UploadError)
    async def _upload_error(request: Request, exc: UploadError):
        return refusal(exc.status, str(exc))

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(request: Request, exc: StarletteHTTPException):
        messages = {404: "no such page or file", 405: "method not allowed here"}
        return refusal(exc.status_code, messages.get(exc.status_code, str(exc.detail)))

    @app.exception_handler(InputError)
    async def _input_error(request: Request, exc: InputError):
        return refusal(422, str(exc))

    @app.get("/", response_class=HTMLResponse)
    async def page() -> HTMLResponse:
        return HTMLResponse(_static_text("index.html"))

    @app.get("/favicon.ico")
    async def favicon() -> Response:
        return Response(status_code=204)

    @app.get("/static/{name}")
    async def static(name: str) -> Response:
        types = {"app.js": "text/javascript", "style.css": "text/css"}
        if name not in types:
            return refusal(404, "no such file")
        return Response(_static_text(name), media_type=types[name])

    @app.get("/api/methods")
    async def methods() -> JSONResponse:
        return JSONResponse(
            {
                "version": __version__,
                "methods": method_catalogue(),
                "limits": {
                    "max_upload_bytes": settings.max_upload_bytes,
                    "max_pixels": settings.max_pixels,
                    "max_side": settings.max_side,
                    "workers": settings.workers,
                    "queue_limit": settings.queue_limit,
                    "job_timeout": settings.job_timeout,
                },
            }
        )

    @app.get("/api/exemplars/builtin")
    async def builtins() -> JSONResponse:
        items = []
        for name in data.BUILTIN:
            found = await asyncio.to_thread(uploads().builtin, name)
            items.append(found.public())
        return JSONResponse({"exemplars": items})

    @app.post("/api/exemplars")
    async def upload(request: Request) -> JSONResponse:
        declared = request.headers.get("content-length")
        length = int(declared) if declared and declared.isdigit() else None
        name = request.headers.get("x-filename")
        if name is not None:
            from urllib.parse import unquote

            name = unquote(name[:1000])
        store = uploads()
        found = await store.receive(request.stream(), name, length)
        return JSONResponse(found.public(), status_code=201)

    @app.get("/api/exemplars/{exemplar_id}/preview")
    async def preview(exemplar_id: str) -> Response:
        found = await asyncio.to_thread(uploads().get, exemplar_id)
        return FileResponse(found.preview, media_type="image/png")

    @app.post("/api/jobs")
    async def submit(request: Request) -> Response:
        body = bytearray()
        async for chunk in request.stream():
            body += chunk
            if len(body) > MAX_JSON_BYTES:
                return refusal(413, f"the request is over {MAX_JSON_BYTES // 1024} KB")
        try:
            payload = json.loads(body.decode("utf-8"))
        except (UnicodeDecodeError, ValueError, RecursionError):  # RecursionError: nested too deep
            return refusal(400, "the request must be JSON")
        plan = await asyncio.to_thread(plan_job, payload, uploads().get, settings)
        try:
            job = jobs().submit(plan)
        except QueueFullError as exc:
            return refusal(503, str(exc))
        return JSONResponse(job.public(token_query(request)), status_code=201)

    @app.get("/api/jobs/{job_id}")
    async def job_state(job_id: str, request: Request) -> JSONResponse:
        return JSONResponse(job_or_404(job_id).public(token_query(request)))

    @app.post("/api/jobs/{job_id}/cancel")
    async def cancel(job_id: str, request: Request) -> JSONResponse:
        job = job_or_404(job_id)
        jobs().cancel(job)
        return JSONResponse(job.public(token_query(request)))

    @app.get("/api/jobs/{job_id}/events")
    async def events(job_id: str, request: Request) -> StreamingResponse:
        job = job_or_404(job_id)
        query = token_query(request)

        async def stream():
            while True:
                changed = job.changed
                yield f"data: {json.dumps(job.public(query))}\n\n"
                if job.state in FINAL_STATES or state.get("stopping"):
                    return
                try:
                    await asyncio.wait_for(changed.wait(), KEEP_ALIVE)
                except TimeoutError:
                    yield ": keep-alive\n\n"
                if state.get("stopping") or await request.is_disconnected():
                    return

        return StreamingResponse(
            stream(), media_type="text/event-stream", headers={"x-accel-buffering": "no"}
        )

    @app.get("/api/jobs/{job_id}/files/{key}")
    async def job_file(job_id: str, key: str, request: Request) -> Response:
        job = job_or_404(job_id)
        item = job.plan.files.get(key)
        if item is None or key not in job.public()["files"]:  # only files of finished steps
            return refusal(404, "no such file for this job")
        path = job.folder / item.filename
        inline = request.query_params.get("inline") == "1"
        headers = {}
        if item.media_type == "text/html":  # the report: shown in a frame, never running scripts
            headers["content-security-policy"] = (
                "sandbox; default-src 'none'; img-src data:; style-src 'unsafe-inline'"
            )
        response = FileResponse(
            path,
            media_type=item.media_type,
            filename=item.download_name,
            content_disposition_type="inline" if inline else "attachment",
            headers=headers,
        )
        return response

    def end_streams() -> None:
        """End every event stream: the server is stopping, and waits for open requests first."""
        state["stopping"] = True
        if "jobs" in state:
            for job in jobs().jobs.values():
                job.touch()

    guard = RequestGuard(app, settings)
    guard.end_streams = end_streams
    return guard
