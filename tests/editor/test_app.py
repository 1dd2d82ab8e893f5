"""The editor's HTTP API, every endpoint, good and bad requests."""

from __future__ import annotations

import io
import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from skimage import data

from wise import effects
from wise.cli import main as wise_main
from wise.editor import session as session_module
from wise.editor.app import COOKIE, create_app
from wise.editor.session import EditorSession
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


@pytest.fixture
def client() -> TestClient:
    template = EditorSession()
    template.choose_effect("xdog")
    return TestClient(create_app(template))


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
    other = TestClient(opened.app)
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
    small = TestClient(create_app(EditorSession(), max_upload_bytes=1000))
    response = small.post("/api/image", content=photo)
    assert response.status_code == 413 and "limit" in response.json()["detail"]
    monkeypatch.setattr(session_module, "MAX_IMAGE_PIXELS", 5000)
    response = TestClient(create_app(EditorSession())).post("/api/image", content=photo)
    assert response.status_code == 400 and "96 pixels is more than" in response.json()["detail"]


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

    fresh = TestClient(opened.app)
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
