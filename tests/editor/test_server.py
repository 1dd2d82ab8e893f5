"""``wise edit``: the starting state, refusals before the server starts, and a real start."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from tests.images import astronaut_png
from wise import effects
from wise.cli import main
from wise.editor.server import _check_port, initial_session, urls
from wise.paramfile import save_params


@pytest.fixture(scope="module")
def photo(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return astronaut_png(tmp_path_factory.mktemp("img") / "photo.png", 80, 60)


def test_initial_session_from_image_and_params(photo: Path, tmp_path: Path) -> None:
    cartoon = effects.create("cartoon")
    params = tmp_path / "p.safetensors"
    save_params(params, cartoon, cartoon.preset("bold"))
    session = initial_session(str(photo), params=str(params))
    state = session.describe()
    assert state["effect"] == "cartoon" and state["content"]["name"] == "photo.png"
    assert state["mask_size"] == [60, 80]
    bins = next(p for p in state["params"] if p["name"] == "bins")
    assert bins["mean"] == pytest.approx(4.0, abs=1e-5)
    assert initial_session(effect="oilpaint", preset="impasto").describe()["preset"] == "impasto"


@pytest.mark.parametrize(
    "extra, message",
    [
        (["missing.png"], "missing.png: no such file"),
        (["--effect", "pencil"], "unknown effect 'pencil'"),
        (["--effect", "cartoon", "--preset", "nope"], "nope"),
        (["--preset", "bold"], "--preset needs --effect"),
        (["--params", "missing.safetensors"], "missing.safetensors: no such file"),
        (["--port", "0"], "--port: must be from 1 to 65,535"),
    ],
)
def test_refusals_are_one_line_with_exit_code_2(
    extra: list[str], message: str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(["edit", *extra]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and err.startswith("wise: error:")


def test_a_port_in_use_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert main(["edit", "--port", str(port)]) == 2
    assert "cannot listen on 127.0.0.1" in capsys.readouterr().err


def test_wise_edit_serves_the_image_on_loopback(photo: Path) -> None:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    command = [sys.executable, "-m", "wise", "edit", str(photo), "--effect", "xdog", "--port", str(port)]
    server = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=os.environ.copy())
    try:
        assert f"http://127.0.0.1:{port}/" in server.stdout.readline()
        deadline = time.monotonic() + 30
        while True:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/state", timeout=5) as response:
                    state = json.load(response)
                break
            except OSError:
                assert time.monotonic() < deadline and server.poll() is None, "the editor did not start"
                time.sleep(0.1)
        assert state["effect"] == "xdog" and state["content"]["width"] == 80
    finally:
        server.terminate()
        server.wait(timeout=10)


def test_urls_to_open() -> None:
    assert urls("127.0.0.1", 8000, None) == ["http://127.0.0.1:8000/"]
    assert urls("::1", 8000, None) == ["http://[::1]:8000/"]
    assert urls("192.168.1.20", 8080, "abc") == ["http://192.168.1.20:8080/?token=abc"]
    assert urls("0.0.0.0", 8000, "abc") == [
        f"http://{socket.gethostname()}:8000/?token=abc",
        "http://127.0.0.1:8000/?token=abc",
    ]


def test_a_port_just_left_by_a_stopped_editor_is_free() -> None:
    with socket.socket() as listening:
        listening.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as uvicorn listens
        listening.bind(("127.0.0.1", 0))
        listening.listen()
        port = listening.getsockname()[1]
        client = socket.create_connection(("127.0.0.1", port))
        accepted, _ = listening.accept()
        accepted.close()  # the server side closes first: its port stays in TIME_WAIT
        client.close()
    _check_port("127.0.0.1", port)
