"""Who may use the editor, and how much a request may send.

Every request passes :class:`Guard` before the app, in this order:

1. **Host**: the ``Host`` header must name the server (``localhost``, ``127.0.0.1``, ``[::1]``
   or the address it listens on), so a page whose own domain was rebound to this machine's
   address (DNS rebinding) gets nothing.
2. **Origin**: a state-changing request (POST, PUT, PATCH, DELETE) sent by a page of another
   origin is refused (its ``Origin`` header, or ``Sec-Fetch-Site``); so are cross-site
   requests for anything but a top-level page load.
3. **Token**: off loopback, a request needs the access token: ``?token=`` in the URL (which
   then sets an HttpOnly cookie), that cookie, or ``Authorization: token ...``.
4. **Size**: a declared ``Content-Length`` over the route's limit is refused at once, unread;
   a chunked body is counted while it is read and cut off at the limit.
"""

from __future__ import annotations

import hmac
import ipaddress
import re
import socket
from dataclasses import dataclass
from urllib.parse import parse_qs, urlsplit

from fastapi.responses import JSONResponse
from starlette.datastructures import Headers, MutableHeaders
from starlette.requests import cookie_parser
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from wise.editor.addresses import WILDCARD_ADDRESSES

MAX_UPLOAD_BYTES = 64 * 1024 * 1024
"""Largest upload (an image or a parameter file)."""
MAX_JSON_BYTES = 1024 * 1024
"""Largest JSON request body. The biggest legal stroke (MAX_POINTS points of 17-digit
coordinates, even pretty-printed) takes about a third of it."""
UPLOAD_PATHS = frozenset({"/api/image", "/api/params"})
"""The routes whose bodies are uploads (MAX_UPLOAD_BYTES); every other body is JSON."""
TOKEN_COOKIE = "wise_token"
LOOPBACK_NAMES = ("localhost", "127.0.0.1", "[::1]")
LOOPBACK_HOSTS = frozenset(LOOPBACK_NAMES)
STATE_CHANGING = frozenset({"POST", "PUT", "PATCH", "DELETE"})
SECURITY_HEADERS = {
    "content-security-policy": "default-src 'self'; img-src 'self' blob: data:; frame-ancestors 'none'",
    "x-content-type-options": "nosniff",
    "referrer-policy": "no-referrer",
}
_HOST_NAME = re.compile(r"[a-z0-9]([a-z0-9.-]*[a-z0-9])?")


def error_response(status: int, message: str) -> JSONResponse:
    """A refusal: the status and a one-line ``detail``."""
    return JSONResponse({"detail": " ".join(message.split())}, status_code=status)


def split_host(value: str) -> tuple[str, int | None] | None:
    """A ``Host`` header (or URL authority) as (lower-case name, port), IPv6 in brackets and
    compressed; None when it is malformed."""
    value = value.strip().lower()
    if value.startswith("["):
        name, bracket, rest = value[1:].partition("]")
        try:
            name = f"[{ipaddress.IPv6Address(name).compressed}]"
        except ValueError:
            return None
        if not bracket or (rest and not rest.startswith(":")):
            return None
        port_text = rest[1:] if rest else None
    else:
        name, colon, port_text = value.partition(":")
        name = name.removesuffix(".")
        if not _HOST_NAME.fullmatch(name):
            return None
        port_text = port_text if colon else None
    if port_text is None:
        return name, None
    if not port_text.isdigit() or not 0 < int(port_text) < 65536:
        return None
    return name, int(port_text)


def _is_ip(name: str) -> bool:
    try:
        ipaddress.ip_address(name.strip("[]"))
    except ValueError:
        return False
    return True


@dataclass(frozen=True)
class Access:
    """Who may use the editor: the Host names it answers to, and off loopback its token."""

    hosts: frozenset[str] = LOOPBACK_HOSTS
    any_ip_host: bool = False
    """Also answer to any IP address as the Host (when listening on all interfaces): DNS
    rebinding needs a domain name, and the token still guards such a server."""
    token: str | None = None
    port: int | None = None
    """The port served, for Origin checks and cookie names (None: the request's own port)."""

    def allows(self, name: str) -> bool:
        return name in self.hosts or (self.any_ip_host and _is_ip(name))

    def cookie(self, base: str) -> str:
        """A cookie name of this server: cookies are shared by every port of a host."""
        return base if self.port is None else f"{base}_{self.port}"

    def shown_hosts(self) -> str:
        names = [n for n in LOOPBACK_NAMES if n in self.hosts] + sorted(self.hosts - LOOPBACK_HOSTS)
        return ", ".join(names) + (" or this machine's IP address" if self.any_ip_host else "")


def access_for(listen: str, port: int, token: str | None) -> Access:
    """The access of a server listening on ``listen``: loopback names, and the address given
    (for a wildcard address, this machine's names and any IP address)."""
    hosts = set(LOOPBACK_HOSTS)
    wildcard = listen.strip().lower() in WILDCARD_ADDRESSES
    if wildcard:
        hosts.update(name.lower() for name in (socket.gethostname(), socket.getfqdn()) if name)
    else:
        shown = f"[{listen}]" if ":" in listen and not listen.startswith("[") else listen
        parsed = split_host(shown)
        if parsed is not None:
            hosts.add(parsed[0])
    return Access(hosts=frozenset(hosts), any_ip_host=wildcard, token=token, port=port)


def _body_limit(path: str, max_upload_bytes: int) -> int:
    return max_upload_bytes if path in UPLOAD_PATHS else MAX_JSON_BYTES


def _size(limit: int) -> str:
    return f"{limit / (1024 * 1024):g} MB" if limit >= 1024 * 1024 else f"{limit:,} bytes"


def too_large(limit: int, path: str) -> str:
    what = "the upload" if path in UPLOAD_PATHS else "the request body"
    return f"{what} is larger than the editor's limit of {_size(limit)} for {path}"


class Guard:
    """Pure ASGI middleware: the Host, Origin, token and body-size checks of every request
    (see the module docstring), and the security headers of every response."""

    def __init__(self, app: ASGIApp, access: Access, max_upload_bytes: int) -> None:
        self.app = app
        self.access = access
        self.max_upload_bytes = max_upload_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "websocket":  # the editor has none
            await send({"type": "websocket.close", "code": 1008})
            return
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = Headers(scope=scope)
        refusal, token_cookie = self._check(scope, headers)

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                out = MutableHeaders(scope=message)
                for name, value in SECURITY_HEADERS.items():
                    out[name] = value
                out.setdefault("cache-control", "no-store")
                if message["status"] == 413:
                    out["connection"] = "close"  # the server reads no more of this request's body
                if token_cookie:
                    out.append("set-cookie", token_cookie)
            await send(message)

        if refusal is not None:
            await refusal(scope, receive, send_with_headers)
        else:
            await self.app(scope, receive, send_with_headers)

    def _check(self, scope: Scope, headers: Headers) -> tuple[JSONResponse | None, str | None]:
        """The refusal of a request (None: it may pass) and the token cookie to set."""
        access, method, path = self.access, scope["method"], scope["path"]
        host = split_host(headers.get("host", ""))
        if host is None or not access.allows(host[0]):
            shown = headers.get("host", "(none)")[:100]
            return error_response(
                403,
                f"host {shown!r} is not served here: use {access.shown_hosts()} "
                "(DNS-rebinding protection refuses other host names)",
            ), None
        if not self._same_origin(method, headers, host):
            return error_response(403, "cross-origin request refused: only the editor's own page may use it"), None
        token_cookie = None
        if access.token is not None:
            expected = access.token.encode()
            valid = {where for where, t in self._tokens(scope, headers).items() if hmac.compare_digest(t, expected)}
            if not valid:
                return error_response(
                    403,
                    "this editor needs its access token: open the URL that wise edit printed at start "
                    "(http://...?token=...)",
                ), None
            if "query" in valid and "cookie" not in valid:
                name = access.cookie(TOKEN_COOKIE)
                token_cookie = f"{name}={access.token}; HttpOnly; Path=/; SameSite=Strict"
        declared = headers.get("content-length", "")
        limit = _body_limit(path, self.max_upload_bytes)
        if declared.isdigit() and int(declared) > limit:
            return error_response(413, too_large(limit, path)), token_cookie
        return None, token_cookie

    def _same_origin(self, method: str, headers: Headers, host: tuple[str, int | None]) -> bool:
        """Whether a request may come from where it comes from: state changes only from the
        editor's own origin; cross-site requests only as top-level page loads."""
        page_load = method == "GET" and headers.get("sec-fetch-mode") == "navigate"
        if headers.get("sec-fetch-site") in ("cross-site", "same-site") and not page_load:
            return False
        origin = headers.get("origin")
        if method not in STATE_CHANGING or origin is None:
            return True
        try:
            parts = urlsplit(origin)
        except ValueError:
            return False
        if parts.scheme != "http" or parts.path or parts.query:
            return False
        found = split_host(parts.netloc)
        if found is None or not self.access.allows(found[0]):
            return False
        ports = {host[1] or 80} | ({self.access.port} if self.access.port else set())
        return (found[1] or 80) in ports

    def _tokens(self, scope: Scope, headers: Headers) -> dict[str, bytes]:
        """The tokens a request supplies, by where: query, header, cookie."""
        supplied = {}
        query = parse_qs(scope.get("query_string", b"").decode("latin-1")).get("token")
        if query:
            supplied["query"] = query[0]
        scheme, _, value = headers.get("authorization", "").partition(" ")
        if scheme.lower() == "token" and value.strip():
            supplied["header"] = value.strip()
        cookie = cookie_parser(headers.get("cookie", "")).get(self.access.cookie(TOKEN_COOKIE))
        if cookie:
            supplied["cookie"] = cookie
        return {where: token.encode("utf-8", "replace") for where, token in supplied.items()}
