"""The editor's HTTP API, every endpoint, good and bad requests."""

from __future__ import annotations

import io
import json
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
import tifffile
import torch
from PIL import Image
from skimage import data

from wise import effects
from wise.cli import main as wise_main
from wise.editor import session as session_module
from wise.editor.access import MAX_JSON_BYTES, TOKEN_COOKIE, Access
from wise.editor.app import COOKIE, EDITS_KEPT_SECONDS, MAX_SESSIONS, create_app
from wise.editor.brush import MAX_POINTS
from wise.editor.session import EditorSession
from wise.io import read_image
from wise.paramfile import load_params, save_params

with warnings.catch_warnings():
    warnings.filterwarnings("ignore", message="Using `httpx` with `starlette.testclient` is deprecated")
    from fastapi.testclient import TestClient


def _png(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(array).save(buffer, format="PNG")
    return buffer.getvalue()


def _decode(content: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(content)))


@pytest.fixture(scope="module")
def photo() -> bytes:
    """The astronaut at 96x128 (rows x columns): small, so previews are quick."""
    return _png(np.asarray(Image.fromarray(data.astronaut()).resize((128, 96), Image.BICUBIC)))


BASE_URL = "http://localhost"
"""What the tests' requests name as their Host: one of the names the editor serves."""


def _client(app: object) -> TestClient:
    """A new browser (its own cookies) of ``app``."""
    return TestClient(app, base_url=BASE_URL)


@pytest.fixture
def client() -> TestClient:
    template = EditorSession()
    template.choose_effect("xdog")
    return _client(create_app(template))


@pytest.fixture
def opened(client: TestClient, photo: bytes) -> TestClient:
    response = client.post("/api/image", content=photo, headers={"X-File-Name": "astronaut.png"})
    assert response.status_code == 200, response.text
    return client


def _param(state: dict, name: str) -> dict:
    return next(p for p in state["params"] if p["name"] == name)


def _stroke(client: TestClient, **changes: object) -> object:
    body = {"param": "brightness", "points": [[0.1, 0.2], [0.9, 0.2]], "radius": 0.1, "hardness": 1.0}
    body.update({"mode": "set", "value": 0.3})
    body.update(changes)
    return client.post("/api/stroke", json=body)


def test_page_and_static_files(client: TestClient) -> None:
    page = client.get("/")
    assert page.status_code == 200 and "wise editor" in page.text
    assert client.get("/static/editor.js").status_code == 200
    assert "default-src 'self'" in page.headers["content-security-policy"]
    assert client.get("/static/%2e%2e/session.py").status_code == 404
    missing = client.get("/api/nothing")
    assert missing.status_code == 404 and missing.json()["detail"]
    assert client.put("/api/undo").status_code == 405


def test_state_describes_the_effect_and_sets_a_session_cookie(client: TestClient) -> None:
    response = client.get("/api/state")
    assert response.status_code == 200 and COOKIE in response.cookies
    state = response.json()
    assert state["effect"] == "xdog" and state["content"] is None
    assert set(state["effects"]) == set(effects.available())
    assert [p["name"] for p in state["params"]] == effects.create("xdog").param_names
    assert not state["can_undo"] and not state["can_redo"]


def test_each_browser_session_keeps_its_own_state(opened: TestClient) -> None:
    other = _client(opened.app)
    assert other.get("/api/state").json()["content"] is None
    assert opened.get("/api/state").json()["content"]["width"] == 128


def test_open_image_sizes_preview_and_masks(client: TestClient) -> None:
    wide = _png(np.zeros((600, 1000, 3), np.uint8))
    state = client.post("/api/image", content=wide, headers={"X-File-Name": "C:\\photos\\../x<y>.png"}).json()
    assert state["content"] == {
        "name": "x_y_.png",
        "width": 1000,
        "height": 600,
        "preview_width": 853,
        "preview_height": 512,
    }
    assert state["mask_size"] == [512, 853]
    preview = client.get("/api/preview")
    assert _decode(preview.content).shape == (512, 853, 3)
    assert _decode(client.get("/api/content").content).shape == (512, 853, 3)


@pytest.mark.parametrize(
    "body, status, message",
    [
        (b"", 400, "empty"),
        (b"not an image at all", 400, "not an image"),
        (_png(np.zeros((4, 4, 3), np.uint8)), 400, "too small"),
    ],
)
def test_open_image_refuses_bad_uploads(client: TestClient, body: bytes, status: int, message: str) -> None:
    response = client.post("/api/image", content=body, headers={"X-File-Name": "bad.png"})
    assert response.status_code == status and message in response.json()["detail"]
    assert "wise-edit-" not in response.json()["detail"]  # no server paths in messages
    assert client.get("/api/state").json()["content"] is None


def test_uploads_are_capped_in_bytes_and_pixels(photo: bytes, monkeypatch: pytest.MonkeyPatch) -> None:
    small = _client(create_app(EditorSession(), max_upload_bytes=1000))
    response = small.post("/api/image", content=photo)
    assert response.status_code == 413 and "limit" in response.json()["detail"]
    monkeypatch.setattr(session_module, "pixel_limit", lambda: 5000)
    response = _client(create_app(EditorSession())).post("/api/image", content=photo)
    assert response.status_code == 400 and "pixels" in response.json()["detail"]


def test_a_float_tiff_opens_as_wise_apply_reads_it(client: TestClient, tmp_path: Path) -> None:
    pixels = np.random.default_rng(0).random((40, 50, 3), dtype=np.float32)
    path = tmp_path / "float.tif"
    tifffile.imwrite(path, pixels, photometric="rgb")
    response = client.post("/api/image", content=path.read_bytes(), headers={"X-File-Name": "float.tif"})
    assert response.status_code == 200, response.text
    assert response.json()["content"]["width"] == 50
    _, session = client.app.state.sessions.get(client.cookies[COOKIE])
    assert torch.equal(session.content.image, read_image(path))


def test_outputs_need_an_image(client: TestClient) -> None:
    for path in ("/api/preview", "/api/content", "/api/export.png"):
        response = client.get(path)
        assert response.status_code == 409 and "open an image" in response.json()["detail"]


def test_effect_and_preset(client: TestClient) -> None:
    state = client.post("/api/effect", json={"effect": "cartoon", "preset": "bold"}).json()
    assert state["effect"] == "cartoon" and state["preset"] == "bold"
    assert _param(state, "bins")["mean"] == pytest.approx(4.0, abs=1e-5)
    response = client.post("/api/effect", json={"effect": "sketchy"})
    assert response.status_code == 400 and "unknown effect" in response.json()["detail"]
    response = client.post("/api/effect", json={"effect": "cartoon", "preset": "nope"})
    assert response.status_code == 400 and "nope" in response.json()["detail"]
    assert client.get("/api/state").json()["preset"] == "bold"  # a refused request changes nothing
    response = client.post("/api/effect", json={})
    assert response.status_code == 422 and "effect" in response.json()["detail"]


def test_global_value_offsets_the_whole_mask(opened: TestClient) -> None:
    _stroke(opened)
    before = _param(opened.get("/api/state").json(), "brightness")
    state = opened.post("/api/global", json={"param": "brightness", "value": 0.1}).json()
    after = _param(state, "brightness")
    assert after["mean"] == pytest.approx(0.1, abs=1e-4)
    assert after["high"] - after["low"] == pytest.approx(before["high"] - before["low"], abs=1e-4)


@pytest.mark.parametrize(
    "body, status, message",
    [
        ({"param": "brightness", "value": 5.0}, 400, "outside its range"),
        ({"param": "nope", "value": 0.0}, 400, "no parameter 'nope'"),
        ({"param": "brightness", "value": "high"}, 422, "value"),
        ({"param": "brightness"}, 422, "value"),
    ],
)
def test_global_value_refuses_bad_requests(opened: TestClient, body: dict, status: int, message: str) -> None:
    response = opened.post("/api/global", json=body)
    assert response.status_code == status and message in response.json()["detail"]


def test_non_finite_numbers_and_malformed_json_are_refused(opened: TestClient) -> None:
    response = opened.post(
        "/api/global", content=b'{"param": "brightness", "value": NaN}', headers={"Content-Type": "application/json"}
    )
    assert response.status_code == 422 and "finite" in response.json()["detail"]
    response = opened.post("/api/stroke", content=b"{not json", headers={"Content-Type": "application/json"})
    assert response.status_code == 422 and response.json()["detail"].startswith("bad request")


def test_stroke_changes_the_mask_and_the_preview_only_where_painted(opened: TestClient) -> None:
    before = _decode(opened.get("/api/preview").content).astype(int)
    version = opened.get("/api/state").json()["version"]
    state = _stroke(opened).json()
    assert state["version"] > version and state["can_undo"]
    painted = _param(state, "brightness")
    assert painted["high"] == pytest.approx(0.3, abs=1e-5) and painted["low"] == pytest.approx(0.0, abs=1e-6)
    response = opened.get("/api/preview")
    assert int(response.headers["X-Wise-Version"]) == state["version"]
    difference = np.abs(_decode(response.content).astype(int) - before).max(axis=2)
    assert difference[17:22, 25:100].mean() > 5  # under the stroke (row 0.2 of 96)
    assert difference[60:, :].max() == 0  # far below it
    mask = _decode(opened.get("/api/mask/brightness").content)
    assert mask.shape == (96, 128, 4)
    assert not np.array_equal(mask[19, 64], mask[80, 64])


@pytest.mark.parametrize(
    "changes, status, message",
    [
        ({"mode": "smudge"}, 422, "mode"),
        ({"value": None}, 400, "needs a value"),
        ({"value": 9.0}, 400, "needs a value"),
        ({"mode": "increase", "amount": 0.0}, 400, "amount"),
        ({"radius": 0.0}, 400, "radius"),
        ({"points": []}, 422, "points"),
        ({"points": [[0.5, 0.5]] * 5000}, 422, "points"),
        ({"points": [[0.5, 0.5, 0.5]]}, 422, "points"),
        ({"param": "nope"}, 400, "nope"),
    ],
)
def test_stroke_refuses_bad_requests(opened: TestClient, changes: dict, status: int, message: str) -> None:
    response = _stroke(opened, **changes)
    assert response.status_code == status and message in response.json()["detail"]
    assert not opened.get("/api/state").json()["can_undo"]


def test_undo_redo_and_reset(opened: TestClient) -> None:
    original = opened.get("/api/preview").content
    _stroke(opened)
    painted = opened.get("/api/preview").content
    state = opened.post("/api/undo").json()
    assert not state["can_undo"] and state["can_redo"]
    assert opened.get("/api/preview").content == original
    assert opened.post("/api/redo").json()["can_undo"]
    assert opened.get("/api/preview").content == painted
    opened.post("/api/global", json={"param": "contour", "value": 2.0})
    state = opened.post("/api/reset", json={"param": "brightness"}).json()
    assert _param(state, "brightness")["high"] == pytest.approx(0.0, abs=1e-6)
    assert _param(state, "contour")["mean"] == pytest.approx(2.0, abs=1e-4)
    opened.post("/api/undo")  # the reset
    state = opened.post("/api/undo").json()  # the global value
    assert _param(state, "contour")["mean"] == pytest.approx(effects.create("xdog").spec("contour").default, abs=1e-4)
    assert opened.post("/api/reset", json={"param": "nope"}).status_code == 400
    while opened.get("/api/state").json()["can_undo"]:
        opened.post("/api/undo")
    response = opened.post("/api/undo")
    assert response.status_code == 400 and "nothing to undo" in response.json()["detail"]
    _stroke(opened)
    assert not opened.get("/api/state").json()["can_redo"]  # a new edit clears what could be redone


def test_mask_of_an_unknown_parameter(opened: TestClient) -> None:
    response = opened.get("/api/mask/nope")
    assert response.status_code == 400 and "nope" in response.json()["detail"]


def test_saved_params_reopen_and_export_matches_wise_apply(opened: TestClient, photo: bytes, tmp_path: Path) -> None:
    _stroke(opened)
    saved = opened.get("/api/params.safetensors")
    assert saved.status_code == 200 and "xdog_params.safetensors" in saved.headers["content-disposition"]
    params_path = tmp_path / "params.safetensors"
    params_path.write_bytes(saved.content)
    masks = load_params(params_path, effects.create("xdog"))
    assert masks.shape == (1, 8, 96, 128)

    exported = opened.get("/api/export.png")
    assert exported.status_code == 200 and "attachment" in exported.headers["content-disposition"]
    image_path = tmp_path / "photo.png"
    image_path.write_bytes(photo)
    applied = tmp_path / "applied.png"
    assert wise_main(["apply", "xdog", str(image_path), "--params", str(params_path), "-o", str(applied)]) == 0
    assert np.array_equal(_decode(exported.content), np.asarray(Image.open(applied)))

    fresh = _client(opened.app)
    fresh.post("/api/effect", json={"effect": "watercolor"})
    state = fresh.post("/api/params", content=saved.content, headers={"X-File-Name": "p.safetensors"}).json()
    assert state["effect"] == "xdog" and state["mask_size"] == [96, 128]
    assert _param(state, "brightness")["high"] == pytest.approx(0.3, abs=1e-5)


def test_open_params_refuses_bad_files(client: TestClient, tmp_path: Path) -> None:
    response = client.post("/api/params", content=b"", headers={"X-File-Name": "p.safetensors"})
    assert response.status_code == 400 and "empty" in response.json()["detail"]
    response = client.post("/api/params", content=b"garbage", headers={"X-File-Name": "p.safetensors"})
    assert response.status_code == 400 and response.json()["detail"].startswith("p.safetensors: not a safetensors")
    cartoon = effects.create("cartoon")
    path = tmp_path / "p.safetensors"
    save_params(path, cartoon, cartoon.default_params())
    header_length = int.from_bytes(path.read_bytes()[:8], "little")
    header = json.loads(path.read_bytes()[8 : 8 + header_length])
    header["__metadata__"]["effect"] = "pencil"
    tampered = json.dumps(header).encode()
    body = len(tampered).to_bytes(8, "little") + tampered + path.read_bytes()[8 + header_length :]
    response = client.post("/api/params", content=body)
    assert response.status_code == 400 and "unknown effect 'pencil'" in response.json()["detail"]
    assert client.get("/api/state").json()["effect"] == "xdog"


def test_values_clamped_in_an_opened_file_are_noted_once(client: TestClient, tmp_path: Path) -> None:
    xdog = effects.create("xdog")
    values = xdog.default_params().clone()
    values[xdog.param_names.index("brightness")] = 0.9  # normalized: beyond the top of the range
    path = tmp_path / "p.safetensors"
    save_params(path, xdog, values)
    response = client.post("/api/params", content=path.read_bytes(), headers={"X-File-Name": "mine.safetensors"})
    notice = response.json()["notice"]
    assert response.status_code == 200 and notice.startswith("mine.safetensors: ") and "brightness" in notice
    assert "wise-edit-" not in notice
    assert _param(response.json(), "brightness")["mean"] == pytest.approx(xdog.spec("brightness").max)
    assert client.get("/api/state").json()["notice"] is None


# ----- bad inputs of every route: status, a one-line detail, the session unchanged ------------------

TIFF_JUNK = b"II*\x00" + b"\x00" * 64
REFUSAL_SECONDS = 1.0
"""A refusal comes before any decoding or rendering work."""
BAD_INPUTS = [
    ("GET", "/", {"headers": {"Host": "attacker.example"}}, 403, "DNS-rebinding"),
    ("GET", "/static/missing.js", {}, 404, "Not Found"),
    ("GET", "/static/%2e%2e/session.py", {}, 404, "Not Found"),
    ("GET", "/api/state", {"headers": {"Host": "attacker.example:8000"}}, 403, "localhost, 127.0.0.1, [::1]"),
    ("GET", "/api/state", {"headers": {"Sec-Fetch-Site": "cross-site"}}, 403, "cross-origin"),
    ("DELETE", "/api/state", {}, 405, "Method Not Allowed"),
    ("GET", "/api/nothing", {}, 404, "Not Found"),
    ("POST", "/api/image", {"content": b""}, 400, "empty"),
    ("POST", "/api/image", {"content": b"not an image at all"}, 400, "not an image"),
    ("POST", "/api/image", {"content": TIFF_JUNK}, 400, "bad.png"),
    ("POST", "/api/image", {"headers": {"Origin": "http://attacker.example"}, "content": b"x"}, 403, "cross-origin"),
    ("POST", "/api/params", {"content": b""}, 400, "empty"),
    ("POST", "/api/params", {"content": b"\xff" * 16}, 400, "not a safetensors"),
    ("POST", "/api/params", {"headers": {"Sec-Fetch-Site": "same-site"}, "content": b"x"}, 403, "cross-origin"),
    ("POST", "/api/effect", {"json": {"effect": "sketchy"}}, 400, "unknown effect"),
    ("POST", "/api/effect", {"json": {"effect": "xdog", "preset": 3}}, 422, "preset"),
    ("POST", "/api/effect", {"json": []}, 422, "bad request"),
    ("POST", "/api/effect", {"content": b'{"effect": "cartoon"}'}, 415, "Content-Type: application/json"),
    ("POST", "/api/effect", {"json": {"effect": "x" * MAX_JSON_BYTES}}, 413, "limit of 1 MB"),
    ("POST", "/api/global", {"json": {"param": "brightness", "value": 5.0}}, 400, "outside its range"),
    ("POST", "/api/global", {"content": b'{"param": "brightness", "value": 1e999}', "json_type": True}, 422, "finite"),
    ("POST", "/api/global", {"content": b"", "json_type": True}, 422, "bad request"),
    ("POST", "/api/stroke", {"json": {"param": "brightness"}}, 422, "points"),
    ("POST", "/api/stroke", {"chunked": b"[" + b"[0.5, 0.5], " * 100_000 + b"]"}, 413, "limit of 1 MB"),
    ("POST", "/api/stroke", {"headers": {"Origin": "null"}, "json": {}}, 403, "cross-origin"),
    ("POST", "/api/reset", {"json": {"param": "nope"}}, 400, "nope"),
    ("POST", "/api/reset", {"json": {}}, 422, "param"),
    ("POST", "/api/undo", {}, 400, "nothing to undo"),
    ("PUT", "/api/undo", {}, 405, "Method Not Allowed"),
    ("POST", "/api/redo", {}, 400, "nothing to redo"),
    ("POST", "/api/redo", {"headers": {"Origin": "http://localhost:9999"}}, 403, "cross-origin"),
    ("GET", "/api/preview", {"fresh": True}, 409, "open an image"),
    ("GET", "/api/content", {"fresh": True}, 409, "open an image"),
    ("GET", "/api/mask/nope", {}, 400, "no parameter 'nope'"),
    ("GET", "/api/mask/%2e%2e", {}, 400, "no parameter '..'"),
    ("GET", "/api/params.safetensors", {"headers": {"Host": "evil.localhost"}}, 403, "DNS-rebinding"),
    ("GET", "/api/export.png", {"fresh": True}, 409, "open an image"),
]


@pytest.mark.parametrize("method, path, request_args, status, message", BAD_INPUTS, ids=lambda v: str(v)[:40])
def test_bad_inputs_of_every_route(
    client: TestClient, photo: bytes, method: str, path: str, request_args: dict, status: int, message: str
) -> None:
    args = dict(request_args)
    if not args.pop("fresh", False):
        assert client.post("/api/image", content=photo).status_code == 200
    if args.pop("json_type", False):
        args["headers"] = {"Content-Type": "application/json"}
    if "chunked" in args:
        body = args.pop("chunked")
        args["content"] = (body[i : i + 65536] for i in range(0, len(body), 65536))
        args["headers"] = {"Content-Type": "application/json"}
    args.setdefault("headers", {}).setdefault("X-File-Name", "bad.png")
    before = client.get("/api/state").json()
    start = time.perf_counter()
    response = client.request(method, path, **args)
    seconds = time.perf_counter() - start
    detail = response.json()["detail"]
    assert response.status_code == status, detail
    assert seconds < REFUSAL_SECONDS, f"refused after {seconds:.2f} s"
    assert message in detail and "\n" not in detail and "Traceback" not in detail
    assert "wise-edit-" not in detail  # no server paths in messages
    assert client.get("/api/state").json() == before


def test_the_biggest_legal_stroke_fits_the_json_limit(opened: TestClient) -> None:
    coordinate = -1.2345678901234567e-05  # as long as a coordinate gets: 17 digits, sign and exponent
    body = {"param": "brightness", "points": [[coordinate, 0.5]] * MAX_POINTS, "radius": 0.1, "mode": "increase"}
    text = json.dumps(body, indent=2)
    assert len(text) < MAX_JSON_BYTES / 2
    response = opened.post("/api/stroke", content=text, headers={"Content-Type": "application/json"})
    assert response.status_code == 200, response.text


# ----- who may use the editor ---------------------------------------------------------------------


def test_a_token_is_needed_off_loopback(photo: bytes) -> None:
    app = create_app(EditorSession(), access=Access(token="secret-token", port=8000))
    browser = TestClient(app, base_url="http://localhost:8000")
    for response in (browser.get("/"), browser.get("/api/state"), browser.get("/?token=wrong")):
        assert response.status_code == 403 and "open the URL" in response.json()["detail"]
    response = browser.get("/?token=secret-token")
    cookie = response.headers["set-cookie"]
    assert response.status_code == 200 and cookie.startswith(f"{TOKEN_COOKIE}_8000=secret-token;")
    assert "HttpOnly" in cookie and "SameSite=Strict" in cookie
    assert browser.get("/api/state").status_code == 200  # the cookie alone
    assert browser.post("/api/image", content=photo, headers={"Origin": "http://localhost:8000"}).status_code == 200
    other = TestClient(app, base_url="http://localhost:8000")
    assert other.get("/api/state", headers={"Authorization": "token secret-token"}).status_code == 200
    assert other.get("/api/state", headers={"Authorization": "token secret"}).status_code == 403


# ----- sessions -------------------------------------------------------------------------------------


def test_page_and_static_files_make_no_session(client: TestClient) -> None:
    for path in ("/", "/static/editor.js", "/static/editor.css"):
        assert COOKIE not in client.get(path).cookies
    assert len(client.app.state.sessions) == 0


def test_new_browsers_never_push_out_a_session_with_edits(opened: TestClient) -> None:
    _stroke(opened)
    for _ in range(3 * MAX_SESSIONS):
        assert _client(opened.app).get("/api/state").status_code == 200
    assert opened.get("/api/state").json()["can_undo"]


def test_a_full_editor_refuses_new_browsers_until_a_session_is_left_alone(client: TestClient) -> None:
    browsers = [client] + [_client(client.app) for _ in range(MAX_SESSIONS - 1)]
    for browser in browsers:
        assert browser.post("/api/global", json={"param": "brightness", "value": 0.1}).status_code == 200
    response = _client(client.app).get("/api/state")
    assert response.status_code == 503 and "the editor is full" in response.json()["detail"]
    _, oldest = client.app.state.sessions.get(browsers[0].cookies[COOKIE])
    oldest.last_edit = time.monotonic() - EDITS_KEPT_SECONDS - 1
    assert _client(client.app).get("/api/state").status_code == 200
    assert browsers[0].get("/api/state").json()["can_undo"] is False  # the one left alone went
    assert all(b.get("/api/state").json()["can_undo"] for b in browsers[1:])


def test_a_quick_preview_shows_a_stroke_at_a_reduced_size(client: TestClient) -> None:
    """The page shows a stroke at once from a quick preview (a seventh of the pixels), then the full one."""
    large = _png(np.asarray(Image.fromarray(data.astronaut()).resize((512, 384), Image.BICUBIC)))
    assert client.post("/api/image", content=large, headers={"X-File-Name": "astronaut.png"}).status_code == 200
    before = _decode(client.get("/api/preview?quick=1").content).astype(int)
    state = _stroke(client).json()
    quick = client.get("/api/preview?quick=1")
    assert int(quick.headers["X-Wise-Version"]) == state["version"]
    shown = _decode(quick.content).astype(int)
    assert shown.shape == before.shape == (192, 256, 3)
    difference = np.abs(shown - before).max(axis=2)
    assert difference[36:42, 40:220].mean() > 5  # under the stroke (row 0.2 of 192)
    assert difference[130:, :].max() == 0  # far below it
    full = client.get("/api/preview")
    assert _decode(full.content).shape == (384, 512, 3)
    assert int(full.headers["X-Wise-Version"]) == state["version"]
