"""Starting the editor: the first session's state from the command line, then uvicorn."""

from __future__ import annotations

import ipaddress
import socket
import sys
from pathlib import Path
from typing import TextIO

from wise import effects
from wise.editor.session import EditorSession
from wise.errors import WiseError

LOOPBACK = "127.0.0.1"


def _read(path: str, what: str) -> bytes:
    file = Path(path)
    if not file.is_file():
        raise WiseError(f"{path}: no such {what} file")
    try:
        return file.read_bytes()
    except OSError as e:
        raise WiseError(f"{path}: cannot read the file ({e.strerror or e})") from None


def initial_session(
    image: str | None = None, params: str | None = None, effect: str | None = None, preset: str | None = None
) -> EditorSession:
    """The state every browser session starts from, checked before the server starts."""
    if params is not None and (effect is not None or preset is not None):
        raise WiseError("--params comes with its own effect; leave out --effect and --preset")
    if preset is not None and effect is None:
        raise WiseError("--preset needs --effect, e.g. --effect watercolor --preset " + preset)
    session = EditorSession()
    if params is not None:
        session.open_params(_read(params, "parameter"), Path(params).name)
    elif effect is not None:
        effects.create(effect)
        session.choose_effect(effect, preset)
    if image is not None:
        session.open_image(_read(image, "image"), Path(image).name)
    return session


def _check_port(host: str, port: int) -> None:
    if not 0 < port < 65536:
        raise WiseError(f"--port must be from 1 to 65535, got {port}")
    try:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        with socket.socket(family, socket.SOCK_STREAM) as probe:
            probe.bind((host, port))
    except OSError as e:
        message = f"cannot listen on {host}:{port} ({e.strerror or e}); choose another --port or --host"
        raise WiseError(message) from None


def _is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def serve(session: EditorSession, host: str = LOOPBACK, port: int = 8000, out: TextIO = sys.stdout) -> None:
    """Serve the editor until interrupted."""
    import uvicorn

    from wise.editor.app import create_app

    _check_port(host, port)
    if not _is_loopback(host):
        print(f"warning: listening on {host}: anyone who can reach this machine can use the editor", file=out)
    shown = f"[{host}]" if ":" in host else host
    print(f"wise editor at http://{shown}:{port}/ (Ctrl-C stops it)", file=out, flush=True)
    uvicorn.run(create_app(session), host=host, port=port, log_level="warning")
