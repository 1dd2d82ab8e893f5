"""The editor's web app: one page and a JSON/PNG API over :class:`EditorSession`.

Each browser gets its own session through a cookie. Edits are small JSON requests that
return the new state; the preview is rendered on request from a snapshot, one render at a
time, so the page keeps sending edits while a render runs. Uploads are raw request bodies
(no multipart), capped in bytes and pixels; nothing in a request names a file on the server.
"""

from __future__ import annotations

import logging
import math
import re
import secrets
import threading
from collections import OrderedDict
from importlib import resources
from typing import Annotated, Callable, Literal

from fastapi import Depends, FastAPI, Request, Response
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, JSONResponse
from fastapi.staticfiles import StaticFiles
from pydantic import AfterValidator, BaseModel, Field
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException as StarletteHTTPException

from wise.editor.brush import MAX_POINTS
from wise.editor.session import EditorSession, NoContent
from wise.errors import WiseError

MAX_UPLOAD_BYTES = 64 * 1024 * 1024
"""Largest upload (an image or a parameter file)."""
MAX_SESSIONS = 16
"""Sessions kept at once; the least recently used one is dropped beyond this."""
COOKIE = "wise_session"
_NAME_CHARACTERS = re.compile(r"[^A-Za-z0-9 ._()-]+")
log = logging.getLogger("wise.editor")


def _finite(value: float) -> float:
    if not math.isfinite(value):
        raise ValueError("must be a finite number")
    return value


Finite = Annotated[float, AfterValidator(_finite)]


class GlobalValue(BaseModel):
    param: str
    value: Finite


class Stroke(BaseModel):
    param: str
    points: list[tuple[Finite, Finite]] = Field(min_length=1, max_length=MAX_POINTS)
    radius: Finite
    hardness: Finite = 0.5
    mode: Literal["increase", "decrease", "set"]
    amount: Finite = 0.25
    value: Finite | None = None


class EffectChoice(BaseModel):
    effect: str
    preset: str | None = None


class ParamName(BaseModel):
    param: str


class SessionStore:
    """Sessions by cookie token, each started as a copy of the template."""

    def __init__(self, template: EditorSession, capacity: int = MAX_SESSIONS) -> None:
        self.template = template
        self.capacity = capacity
        self._sessions: OrderedDict[str, EditorSession] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, token: str | None) -> tuple[str, EditorSession]:
        with self._lock:
            if token is not None and token in self._sessions:
                self._sessions.move_to_end(token)
                return token, self._sessions[token]
            token = secrets.token_urlsafe(24)
            session = self.template.copy()
            self._sessions[token] = session
            while len(self._sessions) > self.capacity:
                self._sessions.popitem(last=False)
            return token, session


def _display_name(header: str | None, fallback: str) -> str:
    """A file name for messages only: the last path part, harmless characters, at most 80."""
    if not header:
        return fallback
    name = _NAME_CHARACTERS.sub("_", header.replace("\\", "/").rsplit("/", 1)[-1]).strip()[:80]
    return name or fallback


async def _body(request: Request, limit: int) -> bytes:
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > limit:
        raise _TooLarge(limit)
    chunks, total = [], 0
    async for chunk in request.stream():
        total += len(chunk)
        if total > limit:
            raise _TooLarge(limit)
        chunks.append(chunk)
    return b"".join(chunks)


class _TooLarge(Exception):
    def __init__(self, limit: int) -> None:
        super().__init__(f"the upload is larger than the editor's limit of {limit // (1024 * 1024)} MB")


def _session(request: Request, response: Response) -> EditorSession:
    """The requesting browser's session (a new one, with its cookie, on the first request)."""
    token, found = request.app.state.sessions.get(request.cookies.get(COOKIE))
    if token != request.cookies.get(COOKIE):
        response.set_cookie(COOKIE, token, httponly=True, samesite="strict")
    return found


Session = Annotated[EditorSession, Depends(_session)]


def _error(status: int, message: str) -> JSONResponse:
    return JSONResponse({"detail": " ".join(message.split())}, status_code=status)


def _validation_message(error: RequestValidationError) -> str:
    problems = []
    for item in error.errors()[:3]:
        where = ".".join(str(part) for part in item.get("loc", ()) if part != "body")
        problems.append(f"{where or 'request'}: {item.get('msg', 'invalid')}")
    return "bad request: " + "; ".join(problems)


def create_app(template: EditorSession, max_upload_bytes: int = MAX_UPLOAD_BYTES) -> FastAPI:
    """The editor app; every new browser session starts as a copy of ``template``."""
    app = FastAPI(title="wise editor", docs_url=None, redoc_url=None, openapi_url=None)
    app.state.sessions = SessionStore(template)
    render_lock = threading.Lock()  # renders are CPU-bound: one at a time keeps each fast
    static = resources.files("wise.editor") / "static"
    app.mount("/static", StaticFiles(directory=str(static)), name="static")

    @app.exception_handler(WiseError)
    async def _bad_input(request: Request, error: WiseError) -> JSONResponse:
        return _error(409 if isinstance(error, NoContent) else 400, str(error))

    @app.exception_handler(_TooLarge)
    async def _too_large(request: Request, error: _TooLarge) -> JSONResponse:
        return _error(413, str(error))

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, error: RequestValidationError) -> JSONResponse:
        return _error(422, _validation_message(error))

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, error: StarletteHTTPException) -> JSONResponse:
        return _error(error.status_code, str(error.detail))

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, error: Exception) -> JSONResponse:
        log.exception("unexpected error in %s %s", request.method, request.url.path)
        return _error(500, f"internal error ({type(error).__name__}); the server log has the details")

    @app.middleware("http")
    async def _headers(request: Request, call_next):  # noqa: ANN001, ANN202 (Starlette's signature)
        response = await call_next(request)
        response.headers["Content-Security-Policy"] = "default-src 'self'; img-src 'self' blob: data:"
        response.headers["X-Content-Type-Options"] = "nosniff"
        response.headers.setdefault("Cache-Control", "no-store")
        return response

    @app.get("/", response_class=HTMLResponse)
    def page() -> HTMLResponse:
        return HTMLResponse((static / "index.html").read_text(encoding="utf-8"))

    @app.get("/api/state")
    def state(s: Session) -> dict:
        return s.describe()

    async def upload(request: Request, open_file: Callable[[bytes, str], None], fallback: str) -> None:
        data = await _body(request, max_upload_bytes)
        await run_in_threadpool(open_file, data, _display_name(request.headers.get("x-file-name"), fallback))

    @app.post("/api/image")
    async def open_image(request: Request, s: Session) -> dict:
        await upload(request, s.open_image, "image")
        return s.describe()

    @app.post("/api/params")
    async def open_params(request: Request, s: Session) -> dict:
        await upload(request, s.open_params, "params")
        return s.describe()

    @app.post("/api/effect")
    def choose_effect(choice: EffectChoice, s: Session) -> dict:
        s.choose_effect(choice.effect, choice.preset)
        return s.describe()

    @app.post("/api/global")
    def set_global(edit: GlobalValue, s: Session) -> dict:
        s.set_global(edit.param, edit.value)
        return s.describe()

    @app.post("/api/stroke")
    def stroke(edit: Stroke, s: Session) -> dict:
        s.stroke(edit.param, edit.points, edit.radius, edit.hardness, edit.mode, edit.amount, edit.value)
        return s.describe()

    @app.post("/api/reset")
    def reset(edit: ParamName, s: Session) -> dict:
        s.reset(edit.param)
        return s.describe()

    @app.post("/api/undo")
    def undo(s: Session) -> dict:
        s.undo()
        return s.describe()

    @app.post("/api/redo")
    def redo(s: Session) -> dict:
        s.redo()
        return s.describe()

    @app.get("/api/preview")
    def preview(s: Session) -> Response:
        snapshot = s.snapshot()
        with render_lock:
            png = s.render_preview(snapshot)
        return Response(png, media_type="image/png", headers={"X-Wise-Version": str(snapshot.version)})

    @app.get("/api/content")
    def content(s: Session) -> Response:
        return Response(s.content_preview(), media_type="image/png")

    @app.get("/api/mask/{param}")
    def mask(param: str, s: Session) -> Response:
        return Response(s.mask_image(param), media_type="image/png")

    @app.get("/api/params.safetensors")
    def save_params(s: Session) -> Response:
        name = f"{s.effect.name}_params.safetensors"
        return Response(
            s.params_file(),
            media_type="application/octet-stream",
            headers={"Content-Disposition": f'attachment; filename="{name}"'},
        )

    @app.get("/api/export.png")
    def export(s: Session) -> Response:
        snapshot = s.snapshot()
        with render_lock:
            png = s.render_full(snapshot)
        stem = (snapshot.content.name.rsplit(".", 1)[0] if snapshot.content else "result") or "result"
        return Response(
            png,
            media_type="image/png",
            headers={"Content-Disposition": f'attachment; filename="{stem}_{snapshot.effect.name}.png"'},
        )

    return app
