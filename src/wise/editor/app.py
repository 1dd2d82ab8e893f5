"""The editor's web app: one page and a JSON/PNG API over :class:`EditorSession`.

Each browser gets its own session through a cookie. Edits are small JSON requests that
return the new state; the preview is rendered on request from a snapshot, one render at a
time, so the page keeps sending edits while a render runs. Uploads are raw request bodies
(no multipart); nothing in a request names a file on the server.

Every request passes :class:`wise.editor.access.Guard` first (Host, Origin, token, size).

Request bodies are read on the event loop without blocking it, and decoded and validated in a
worker thread, as are all edits and renders; so a client sending a big or slow body never
holds up another browser's requests.

Sessions: at most :data:`MAX_SESSIONS` are kept. A session with edits (opened a file, painted,
moved a slider, ...) in the last :data:`EDITS_KEPT_SECONDS` is never dropped for a new
browser: when the store is full, the least recently used session without such edits goes; if
every session has recent edits, the new browser gets 503 until one has been left alone that
long. Requests for the page and its static files make no session.
"""

from __future__ import annotations

import logging
import math
import re
import secrets
import threading
import time
from collections import OrderedDict
from importlib import resources
from typing import Annotated, Callable, Literal, TypeVar

from fastapi import Depends, FastAPI, Request, Response
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, JSONResponse
from fastapi.staticfiles import StaticFiles
from pydantic import AfterValidator, BaseModel, Field, ValidationError
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.requests import ClientDisconnect

from wise.editor.access import (
    MAX_JSON_BYTES,
    MAX_UPLOAD_BYTES,
    UPLOAD_PATHS,
    Access,
    Guard,
    error_response,
    too_large,
)
from wise.editor.brush import MAX_POINTS
from wise.editor.session import EditorSession, NoContent
from wise.errors import WiseError

MAX_SESSIONS = 16
"""Browser sessions kept at once."""
EDITS_KEPT_SECONDS = 30 * 60
"""A session edited within this time is never dropped to make room for another browser: long
enough for a break away from the page, short enough that tabs left open a whole day do not
lock others out."""
COOKIE = "wise_session"
_NAME_CHARACTERS = re.compile(r"[^A-Za-z0-9 ._()-]+")
log = logging.getLogger("wise.editor")
ModelT = TypeVar("ModelT", bound=BaseModel)


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


# ----- sessions --------------------------------------------------------------------------------


class EditorFull(Exception):
    """No session can be dropped to make room for a new browser."""


class SessionStore:
    """Sessions by cookie value, each started as a copy of the template; see the module
    docstring for which session goes when the store is full."""

    def __init__(
        self, template: EditorSession, capacity: int = MAX_SESSIONS, keep_edits_for: float = EDITS_KEPT_SECONDS
    ) -> None:
        self.template = template
        self.capacity = capacity
        self.keep_edits_for = keep_edits_for
        self._sessions: OrderedDict[str, EditorSession] = OrderedDict()  # least recently used first
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._sessions)

    def get(self, key: str | None) -> tuple[str, EditorSession]:
        """The session of a cookie value; a new one (and its key) for an unknown or missing one."""
        with self._lock:
            if key is not None and key in self._sessions:
                self._sessions.move_to_end(key)
                return key, self._sessions[key]
            if len(self._sessions) >= self.capacity:
                self._make_room()
            key = secrets.token_urlsafe(24)
            session = self.template.copy()
            self._sessions[key] = session
            return key, session

    def _make_room(self) -> None:
        since = time.monotonic() - self.keep_edits_for
        for key, session in self._sessions.items():
            if not session.has_edits(since):
                del self._sessions[key]
                return
        minutes = f"{self.keep_edits_for / 60:g}"
        raise EditorFull(
            f"the editor is full: all {self.capacity} browser sessions were edited in the last {minutes} minutes; "
            f"a place frees when one has had no edit for {minutes} minutes, or restart wise edit "
            "(after saving the parameters)"
        )


def _display_name(header: str | None, fallback: str) -> str:
    """A file name for messages only: the last path part, harmless characters, at most 80."""
    if not header:
        return fallback
    name = _NAME_CHARACTERS.sub("_", header.replace("\\", "/").rsplit("/", 1)[-1]).strip()[:80]
    return name or fallback


class _Aborted(Exception):
    """The client went away while sending its request body."""


async def _body(request: Request, limit: int) -> bytes:
    """The request body, refused once it exceeds ``limit`` (the Guard refused a declared
    Content-Length over it already; this counts a chunked one)."""
    chunks, total = [], 0
    try:
        async for chunk in request.stream():
            total += len(chunk)
            if total > limit:
                raise StarletteHTTPException(413, too_large(limit, request.url.path))
            chunks.append(chunk)
    except ClientDisconnect:
        what = "upload" if request.url.path in UPLOAD_PATHS else "request"
        raise _Aborted(f"{what} to {request.url.path} aborted by the client") from None
    return b"".join(chunks)


async def _json_body(request: Request, model: type[ModelT]) -> ModelT:
    """A JSON body as ``model``: read with the limit, decoded and validated in a worker thread."""
    content_type = request.headers.get("content-type", "").partition(";")[0].strip().lower()
    if content_type != "application/json":
        raise StarletteHTTPException(415, "send the request body as JSON (Content-Type: application/json)")
    data = await _body(request, MAX_JSON_BYTES)
    try:
        return await run_in_threadpool(model.model_validate_json, data)
    except ValidationError as e:
        raise StarletteHTTPException(422, _validation_message(e.errors())) from None


async def _edited(s: EditorSession, change: Callable[..., object], *args: object) -> dict:
    """Apply an edit in a worker thread; the new state."""

    def run() -> dict:
        change(*args)
        return s.describe()

    return await run_in_threadpool(run)


def _session(request: Request, response: Response) -> EditorSession:
    """The requesting browser's session (a new one, with its cookie, on the first request)."""
    name = request.app.state.cookie
    key, found = request.app.state.sessions.get(request.cookies.get(name))
    if key != request.cookies.get(name):
        response.set_cookie(name, key, httponly=True, samesite="strict")
    return found


Session = Annotated[EditorSession, Depends(_session)]


def _validation_message(errors: list) -> str:
    problems = []
    for item in errors[:3]:
        where = ".".join(str(part) for part in item.get("loc", ()) if part != "body")
        problems.append(f"{where or 'request'}: {item.get('msg', 'invalid')}")
    return "bad request: " + "; ".join(problems)


def create_app(
    template: EditorSession, max_upload_bytes: int = MAX_UPLOAD_BYTES, access: Access | None = None
) -> FastAPI:
    """The editor app; every new browser session starts as a copy of ``template``. ``access``
    defaults to loopback host names without a token."""
    access = access or Access()
    app = FastAPI(title="wise editor", docs_url=None, redoc_url=None, openapi_url=None)
    app.state.sessions = SessionStore(template)
    app.state.cookie = access.cookie(COOKIE)
    app.state.access = access
    render_lock = threading.Lock()  # renders are CPU-bound: one at a time keeps each fast
    static = resources.files("wise.editor") / "static"
    app.mount("/static", StaticFiles(directory=str(static)), name="static")
    app.add_middleware(Guard, access=access, max_upload_bytes=max_upload_bytes)

    @app.exception_handler(WiseError)
    async def _bad_input(request: Request, error: WiseError) -> JSONResponse:
        return error_response(409 if isinstance(error, NoContent) else 400, str(error))

    @app.exception_handler(EditorFull)
    async def _full(request: Request, error: EditorFull) -> JSONResponse:
        return error_response(503, str(error))

    @app.exception_handler(_Aborted)
    async def _aborted(request: Request, error: _Aborted) -> Response:
        log.warning("%s", error)
        return Response(status_code=400)  # nobody is left to read it

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, error: RequestValidationError) -> JSONResponse:
        return error_response(422, _validation_message(list(error.errors())))

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, error: StarletteHTTPException) -> JSONResponse:
        return error_response(error.status_code, str(error.detail))

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, error: Exception) -> JSONResponse:
        # one line here: the server logs the traceback itself
        log.error("unexpected error in %s %s: %s", request.method, request.url.path, type(error).__name__)
        return error_response(500, f"internal error ({type(error).__name__}); the server log has the details")

    @app.get("/", response_class=HTMLResponse)
    def page() -> HTMLResponse:
        return HTMLResponse((static / "index.html").read_text(encoding="utf-8"))

    @app.get("/api/state")
    def state(s: Session) -> dict:
        return s.describe()

    async def upload(request: Request, s: EditorSession, open_file: Callable[[bytes, str], None], name: str) -> dict:
        data = await _body(request, max_upload_bytes)
        return await _edited(s, open_file, data, _display_name(request.headers.get("x-file-name"), name))

    @app.post("/api/image")
    async def open_image(request: Request, s: Session) -> dict:
        return await upload(request, s, s.open_image, "image")

    @app.post("/api/params")
    async def open_params(request: Request, s: Session) -> dict:
        return await upload(request, s, s.open_params, "params")

    @app.post("/api/effect")
    async def choose_effect(request: Request, s: Session) -> dict:
        choice = await _json_body(request, EffectChoice)
        return await _edited(s, s.choose_effect, choice.effect, choice.preset)

    @app.post("/api/global")
    async def set_global(request: Request, s: Session) -> dict:
        edit = await _json_body(request, GlobalValue)
        return await _edited(s, s.set_global, edit.param, edit.value)

    @app.post("/api/stroke")
    async def stroke(request: Request, s: Session) -> dict:
        e = await _json_body(request, Stroke)
        return await _edited(s, s.stroke, e.param, e.points, e.radius, e.hardness, e.mode, e.amount, e.value)

    @app.post("/api/reset")
    async def reset(request: Request, s: Session) -> dict:
        edit = await _json_body(request, ParamName)
        return await _edited(s, s.reset, edit.param)

    @app.post("/api/undo")
    def undo(s: Session) -> dict:
        s.undo()
        return s.describe()

    @app.post("/api/redo")
    def redo(s: Session) -> dict:
        s.redo()
        return s.describe()

    @app.get("/api/preview")
    def preview(s: Session, quick: bool = False) -> Response:
        """The preview of the current state; ``quick=1`` a reduced one that renders in a fraction
        of the time, for the page to show at once while it asks for the full one."""
        with render_lock:  # the state when its turn comes: a request that waited is not drawn stale
            snapshot = s.snapshot()
            png = s.render_quick(snapshot) if quick else s.render_preview(snapshot)
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
