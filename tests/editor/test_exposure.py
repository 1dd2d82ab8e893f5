"""Who can reach the editor and what one client can do to the others: the real server (uvicorn in a
subprocess, as ``wise edit`` starts it), requests over its real HTTP stack."""

from __future__ import annotations

import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, TextIO

import httpx
import psutil
import pytest

from tests.images import astronaut_png

START_SECONDS = 60
"""Longest wait for a server to answer (it imports torch and opens the image first)."""
LAUNCH = (
    "import sys; from wise.editor.server import initial_session, serve; "
    "serve(initial_session(sys.argv[1], effect='xdog'), sys.argv[2], int(sys.argv[3]))"
)
STROKE = {"param": "brightness", "points": [[0.2, 0.5], [0.8, 0.5]], "radius": 0.1, "mode": "set", "value": 0.3}
BIG = 50 * 1024 * 1024


@dataclass
class Server:
    """A running editor: its process, port, the URLs it printed and its stderr so far."""

    process: subprocess.Popen
    port: int
    printed: list[str]
    errors: list[str] = field(default_factory=list)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def token(self) -> str:
        return next(line for line in self.printed if "?token=" in line).split("?token=")[1].split()[0]

    def rss(self) -> int:
        return psutil.Process(self.process.pid).memory_info().rss


def _free_port(address: str) -> int:
    with socket.socket() as probe:
        probe.bind((address, 0))
        return probe.getsockname()[1]


def _collect(stream: TextIO, lines: list[str]) -> None:
    for line in stream:
        lines.append(line)


def _start(image: Path, host: str) -> Iterator[Server]:
    port = _free_port(host)
    command = [sys.executable, "-c", LAUNCH, str(image), host, str(port)]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    server = Server(process, port, [])
    threading.Thread(target=_collect, args=(process.stderr, server.errors), daemon=True).start()
    try:
        deadline = time.monotonic() + START_SECONDS
        while True:
            assert process.poll() is None, f"the editor stopped: {''.join(server.errors)}"
            assert time.monotonic() < deadline, "the editor did not start"
            try:
                httpx.get(server.url + "/static/editor.css", timeout=2)
                break
            except httpx.TransportError:
                time.sleep(0.1)
        line = process.stdout.readline()
        while line:
            server.printed.append(line)
            if "wise editor at" in line:
                break
            line = process.stdout.readline()
        yield server
    finally:
        process.terminate()
        process.wait(timeout=10)


@pytest.fixture(scope="module")
def photo(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return astronaut_png(tmp_path_factory.mktemp("img") / "photo.png", 96, 72)


@pytest.fixture(scope="module")
def server(photo: Path) -> Iterator[Server]:
    yield from _start(photo, "127.0.0.1")


@pytest.fixture(scope="module")
def open_server(photo: Path) -> Iterator[Server]:
    """The editor listening on every interface: it needs its token."""
    yield from _start(photo, "0.0.0.0")


def _browser(server: Server) -> httpx.Client:
    return httpx.Client(base_url=server.url, timeout=30)


def _raw(server: Server, head: str) -> socket.socket:
    """A connection that has sent ``head`` (request line and headers, without the blank line)."""
    connection = socket.create_connection(("127.0.0.1", server.port), timeout=10)
    connection.sendall(head.replace("\n", "\r\n").encode() + b"\r\n\r\n")
    return connection


def _status(connection: socket.socket) -> int:
    reply = b""
    while b"\r\n" not in reply:
        chunk = connection.recv(4096)
        assert chunk, "the server closed the connection without a reply"
        reply += chunk
    return int(reply.split()[1])


def _send_quietly(connection: socket.socket, chunks: Iterator[bytes]) -> None:
    """Send until the server stops reading (it closes the connection after refusing a body)."""
    try:
        for chunk in chunks:
            connection.sendall(chunk)
    except OSError:
        pass


# ----- Host --------------------------------------------------------------------------------------


@pytest.mark.parametrize("path", ["/", "/api/state", "/api/export.png", "/static/editor.js", "/missing"])
@pytest.mark.parametrize("host", ["attacker.example", "attacker.example:{port}", "127.0.0.1.nip.io:{port}"])
def test_a_foreign_host_gets_nothing(server: Server, path: str, host: str) -> None:
    response = httpx.get(server.url + path, headers={"Host": host.format(port=server.port)})
    assert response.status_code == 403 and "set-cookie" not in response.headers
    detail = response.json()["detail"]
    assert "localhost, 127.0.0.1, [::1]" in detail and "DNS-rebinding" in detail


@pytest.mark.parametrize("host", ["localhost:{port}", "127.0.0.1:{port}", "localhost", "[::1]:{port}"])
def test_the_served_host_names_answer(server: Server, host: str) -> None:
    for path in ("/", "/api/state", "/static/editor.js"):
        assert httpx.get(server.url + path, headers={"Host": host.format(port=server.port)}).status_code == 200


# ----- Origin ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "headers",
    [
        {"Origin": "http://attacker.example"},
        {"Origin": "http://localhost:1"},
        {"Origin": "https://127.0.0.1:{port}"},
        {"Origin": "null"},
        {"Sec-Fetch-Site": "cross-site"},
        {"Origin": "http://127.0.0.1:{port}", "Sec-Fetch-Site": "same-site"},
    ],
)
def test_state_changes_from_another_origin_are_refused(server: Server, headers: dict) -> None:
    headers = {name: value.format(port=server.port) for name, value in headers.items()}
    with _browser(server) as browser:
        before = browser.get("/api/state").json()
        for path, body in (("/api/stroke", STROKE), ("/api/effect", {"effect": "cartoon"}), ("/api/undo", None)):
            response = browser.post(path, json=body, headers=headers)
            assert response.status_code == 403 and "cross-origin" in response.json()["detail"]
        assert browser.get("/api/state").json() == before


def test_state_changes_from_the_page_or_without_an_origin_pass(server: Server) -> None:
    with _browser(server) as browser:
        for origin in (f"http://127.0.0.1:{server.port}", f"http://localhost:{server.port}"):
            page = {"Origin": origin, "Sec-Fetch-Site": "same-origin"}
            assert browser.post("/api/stroke", json=STROKE, headers=page).status_code == 200
        assert browser.post("/api/undo").status_code == 200  # e.g. curl


# ----- token -------------------------------------------------------------------------------------


def test_off_loopback_a_token_is_needed(open_server: Server) -> None:
    assert any("warning: listening on 0.0.0.0" in line for line in open_server.printed)
    token = open_server.token()
    with _browser(open_server) as browser:
        for path in ("/", "/api/state", "/static/editor.js", f"/?token={token[:-1]}"):
            response = browser.get(path)
            assert response.status_code == 403 and "open the URL" in response.json()["detail"]
        response = browser.get(f"/?token={token}")
        assert response.status_code == 200 and "wise editor" in response.text
        cookie = response.headers["set-cookie"]
        assert f"={token};" in cookie and "HttpOnly" in cookie and "SameSite=Strict" in cookie
        assert browser.get("/api/state").status_code == 200  # the cookie alone
        assert browser.post("/api/stroke", json=STROKE).status_code == 200
        assert browser.get("/api/state", headers={"Host": "attacker.example"}).status_code == 403
    assert httpx.get(open_server.url + "/api/state", headers={"Authorization": f"token {token}"}).status_code == 200
    wrong = httpx.get(open_server.url + "/api/state", cookies={f"wise_token_{open_server.port}": token[::-1]})
    assert wrong.status_code == 403


# ----- bodies ------------------------------------------------------------------------------------


def test_a_50_mb_json_body_is_refused_at_once_unread(server: Server) -> None:
    before = server.rss()
    heads = [
        f"POST /api/stroke HTTP/1.1\nHost: 127.0.0.1\nContent-Type: application/json\nContent-Length: {BIG}",
        "POST /api/stroke HTTP/1.1\nHost: 127.0.0.1\nContent-Type: application/json\nTransfer-Encoding: chunked",
    ]
    for head in heads:
        started = time.monotonic()
        connection = _raw(server, head)
        piece = b"x" * 65536
        chunks = (piece if "Content-Length" in head else b"10000\r\n" + piece + b"\r\n" for _ in range(BIG // 65536))
        sender = threading.Thread(target=_send_quietly, args=(connection, chunks))
        sender.start()
        with _browser(server) as other:  # another session, answered while the big body is sent
            asked = time.monotonic()
            assert other.get("/api/state").status_code == 200
            answered = time.monotonic() - asked
        assert _status(connection) == 413
        refused = time.monotonic() - started
        assert refused < 1.0 and answered < 1.0
        sender.join()
        connection.close()
        print(f"{head.splitlines()[-1]}: 413 after {refused:.3f} s, another session answered in {answered:.3f} s")
    growth = server.rss() - before
    print(f"server memory growth {growth / 2**20:.1f} MB")
    assert growth < 100 * 1024 * 1024


def test_another_browser_is_answered_while_a_slow_body_arrives(server: Server) -> None:
    body = b'{"param": "brightness", "mode": "set", "value": 0.3, "radius": 0.1, "points": ['
    body += b"[0.5, 0.5], " * 4000 + b"[0.5, 0.5]]}"
    head = f"POST /api/stroke HTTP/1.1\nHost: 127.0.0.1\nContent-Type: application/json\nContent-Length: {len(body)}"
    connection = _raw(server, head)
    pieces = [body[i : i + 2048] for i in range(0, len(body), 2048)]
    sender = threading.Thread(target=lambda: [connection.sendall(p) or time.sleep(0.05) for p in pieces])
    sender.start()
    with _browser(server) as other:
        while sender.is_alive():
            started = time.monotonic()
            assert other.get("/api/state").status_code == 200
            assert other.post("/api/stroke", json=STROKE).status_code == 200
            assert time.monotonic() - started < 1.0
    sender.join()
    assert _status(connection) == 200
    connection.close()


def test_a_client_gone_mid_upload_is_one_line_in_the_log(server: Server) -> None:
    logged = len(server.errors)
    connection = _raw(server, "POST /api/image HTTP/1.1\nHost: 127.0.0.1\nContent-Length: 10485760")
    connection.sendall(b"\0" * 1024 * 1024)
    connection.close()
    deadline = time.monotonic() + 5
    while len(server.errors) == logged and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.3)  # anything else it would log
    new = server.errors[logged:]
    assert new == ["wise.editor: upload to /api/image aborted by the client\n"]
    assert not any("Traceback" in line for line in server.errors)
    assert httpx.get(server.url + "/api/state").status_code == 200


# ----- sessions ----------------------------------------------------------------------------------


def test_new_visitors_do_not_drop_a_session_with_edits(server: Server) -> None:
    with _browser(server) as editing:
        assert editing.post("/api/stroke", json=STROKE).status_code == 200
        painted = editing.get("/api/state").json()
        for _ in range(40):
            assert httpx.get(server.url + "/api/state").status_code == 200
        assert editing.get("/api/state").json() == painted
