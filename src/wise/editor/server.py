"""Starting the editor: the first session's state from the command line, then uvicorn.

On a loopback address the editor answers without a token; on any other address :func:`serve`
makes a random access token, which the URL it prints carries (see :mod:`wise.editor.app`).
"""

from __future__ import annotations

import asyncio
import ipaddress
import logging
import secrets
import socket
import sys
from pathlib import Path
from typing import TextIO

from wise import effects
from wise.editor.addresses import LOOPBACK, WILDCARD_ADDRESSES
from wise.editor.session import EditorSession
from wise.editor.start import check_start
from wise.errors import WiseError
from wise.files import MAX_PARAMS_BYTES, open_regular
from wise.io import MAX_IMAGE_BYTES
from wise.ppn.predictor import LocalPredictor

"""Listen addresses that mean every interface."""
TOKEN_BYTES = 32
"""Random bytes in an access token (43 URL-safe characters)."""


def _read(path: str, what: str, max_bytes: int) -> bytes:
    """A file named on the command line, refused unless a regular file within ``max_bytes``."""
    with open_regular(path, what, max_bytes) as file:
        return file.read(max_bytes + 1)


def initial_session(
    image: str | None = None,
    params: str | None = None,
    effect: str | None = None,
    preset: str | None = None,
    model: str | None = None,
) -> EditorSession:
    """The state every browser session starts from, checked before the server starts; with
    ``model`` (a translator), results are its CNN's drawings of the effect's output."""
    check_start(image, params, effect, preset, model)
    session = EditorSession()
    if params is not None:
        session.open_params(_read(params, "parameter file", MAX_PARAMS_BYTES), Path(params).name)
    elif effect is not None:
        effects.create(effect)
        session.choose_effect(effect, preset)
    if model is not None:
        session.use_translator(LocalPredictor(model, session.effect.name))
    if image is not None:
        session.open_image(_read(image, "image", MAX_IMAGE_BYTES), Path(image).name)
    return session


def _check_port(host: str, port: int) -> None:
    if not 0 < port < 65536:
        raise WiseError(f"--port must be from 1 to 65535, got {port}")
    try:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        with socket.socket(family, socket.SOCK_STREAM) as probe:
            if sys.platform != "win32":  # as uvicorn binds: a port left in TIME_WAIT by a stopped editor is free
                probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            probe.bind((host, port))
    except OSError as e:
        message = f"cannot listen on {host}:{port} ({e.strerror or e}); choose another --port or --host"
        raise WiseError(message) from None


def _is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def _url_host(host: str) -> str:
    return f"[{host}]" if ":" in host else host


def urls(host: str, port: int, token: str | None) -> list[str]:
    """The addresses to open the editor at: the one it listens on (this machine's name for a
    wildcard address, then also 127.0.0.1), with the token if there is one."""
    query = f"?token={token}" if token else ""
    if host.strip().lower() in WILDCARD_ADDRESSES:
        return [f"http://{_url_host(name)}:{port}/{query}" for name in (socket.gethostname() or LOOPBACK, LOOPBACK)]
    return [f"http://{_url_host(host)}:{port}/{query}"]


def _log_to(stream: TextIO) -> None:
    """The editor's own messages (e.g. an aborted upload) as one line each, named."""
    logger = logging.getLogger("wise.editor")
    if not logger.handlers:
        handler = logging.StreamHandler(stream)
        handler.setFormatter(logging.Formatter("%(name)s: %(message)s"))
        logger.addHandler(handler)
        logger.setLevel(logging.INFO)
        logger.propagate = False


def serve(session: EditorSession, host: str = LOOPBACK, port: int = 8000, out: TextIO = sys.stdout) -> None:
    """Serve the editor until interrupted; off loopback with a new access token."""
    import uvicorn

    from wise.editor.access import access_for
    from wise.editor.app import create_app

    _check_port(host, port)
    token = None if _is_loopback(host) else secrets.token_urlsafe(TOKEN_BYTES)
    if token is not None:
        print(
            f"warning: listening on {host}: anyone who can reach this machine and has the URL below "
            "(its token) can use the editor",
            file=out,
        )
    app = create_app(session, access=access_for(host, port, token))
    _log_to(sys.stderr)
    server = uvicorn.Server(uvicorn.Config(app, host=host, port=port, log_level="warning"))

    async def serve_and_announce() -> None:
        # the addresses are printed once the server listens and Ctrl-C is its own to handle
        serving = asyncio.ensure_future(server.serve())
        while not (server.started or serving.done()):
            await asyncio.sleep(0.02)
        if server.started:
            first, *others = urls(host, port, token)
            print(f"wise editor at {first} (Ctrl-C stops it)", file=out)
            for url in others:
                print(f"  or {url}", file=out)
            out.flush()
        await serving

    asyncio.run(serve_and_announce())
    if not server.started:
        raise WiseError(f"the editor could not listen on {host} port {port}; try another --port")
