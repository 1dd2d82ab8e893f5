"""End to end: the editor page in headless Chromium (Debian's package, driven by Playwright)."""

from __future__ import annotations

import base64
import io
import os
import shutil
import socket
import threading
import time
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest
from PIL import Image
from skimage import data

from wise.cli import main as wise_main

CHROMIUM = Path(os.environ.get("WISE_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium")
SCREENSHOT_ENV = "WISE_EDITOR_SCREENSHOT"
"""Where to copy the screenshot the test takes (the README's picture): ``make screenshot``."""
CHROMIUM_FLAGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]

playwright_api = pytest.importorskip("playwright.sync_api", reason="the playwright package is not installed")
pytestmark = pytest.mark.skipif(
    not CHROMIUM.exists(),
    reason=f"no Chromium at {CHROMIUM}: install Debian's chromium package (apt-get install chromium)",
)


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.fixture(scope="module")
def editor_url() -> Iterator[str]:
    import uvicorn

    from wise.editor.app import create_app
    from wise.editor.session import EditorSession

    template = EditorSession()
    template.choose_effect("cartoon")
    port = _free_port()
    server = uvicorn.Server(uvicorn.Config(create_app(template), host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 30
    while not server.started:
        assert time.monotonic() < deadline, "the editor server did not start"
        time.sleep(0.05)
    yield f"http://127.0.0.1:{port}/"
    server.should_exit = True
    thread.join(timeout=10)


@pytest.fixture(scope="module")
def browser() -> Iterator[object]:
    with playwright_api.sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_FLAGS)
        yield chromium
        chromium.close()


def _wait_until_shown(page) -> None:  # noqa: ANN001
    """Until the page shows the preview of the server's newest state, idle."""
    page.wait_for_function(
        "() => { const s = document.getElementById('status');"
        " return s.dataset.state === 'ready' && s.dataset.version === s.dataset.target; }",
        timeout=60_000,
    )


def _preview(page) -> np.ndarray:  # noqa: ANN001
    """The preview the server renders for this browser's session (same cookie)."""
    response = page.request.get("/api/preview")
    assert response.ok, response.text()
    return np.asarray(Image.open(io.BytesIO(response.body())).convert("RGB")).astype(np.int16)


def _on_screen(page) -> np.ndarray:  # noqa: ANN001
    """The preview image the page shows, read back from the browser."""
    url = page.eval_on_selector(
        "#preview",
        "img => { const c = document.createElement('canvas'); c.width = img.naturalWidth;"
        " c.height = img.naturalHeight; c.getContext('2d').drawImage(img, 0, 0); return c.toDataURL('image/png'); }",
    )
    raw = base64.b64decode(url.split(",", 1)[1])
    return np.asarray(Image.open(io.BytesIO(raw)).convert("RGB")).astype(np.int16)


def _drag(page, start: tuple[float, float], end: tuple[float, float], steps: int = 12) -> None:  # noqa: ANN001
    """A left-button drag across the painting layer, in fractions of its size."""
    box = page.locator("#paint").bounding_box()
    x0, y0 = box["x"] + start[0] * box["width"], box["y"] + start[1] * box["height"]
    x1, y1 = box["x"] + end[0] * box["width"], box["y"] + end[1] * box["height"]
    page.mouse.move(x0, y0)
    page.mouse.down()
    page.mouse.move(x1, y1, steps=steps)
    page.mouse.up()


def _band(image: np.ndarray, rows: tuple[float, float], cols: tuple[float, float]) -> np.ndarray:
    h, w = image.shape[:2]
    return image[int(rows[0] * h) : int(rows[1] * h), int(cols[0] * w) : int(cols[1] * w)]


def test_paint_undo_repaint_save_and_export(editor_url: str, browser, tmp_path: Path) -> None:  # noqa: ANN001
    photo = tmp_path / "astronaut.png"
    Image.fromarray(data.astronaut()).resize((768, 768), Image.BICUBIC).save(photo)
    context = browser.new_context(base_url=editor_url, viewport={"width": 1280, "height": 820}, accept_downloads=True)
    page = context.new_page()
    page.goto(editor_url)
    page.set_input_files("#open-image", str(photo))
    _wait_until_shown(page)
    before = _preview(page)
    assert np.array_equal(_on_screen(page), before)

    page.check("#pick-saturation")
    page.check("input[name=brush-mode][value=set]")
    page.fill("#brush-value", "0")
    page.locator("#brush-size").fill("60")
    page.locator("#brush-hardness").fill("80")
    stroke = ((0.15, 0.3), (0.85, 0.3))
    page.evaluate(
        "() => { window.previewLoads = []; const img = document.getElementById('preview');"
        " img.addEventListener('load', () => window.previewLoads.push(img.naturalWidth)); }"
    )
    _drag(page, *stroke)
    _wait_until_shown(page)
    loads = page.evaluate("() => window.previewLoads")
    assert loads[0] == 192 and loads[-1] == 512, f"quick preview first, then the full one: {loads}"
    assert page.locator("#preview").bounding_box()["width"] > 400  # the quick one is shown at the full size
    painted = _preview(page)
    assert np.array_equal(_on_screen(page), painted)
    difference = np.abs(painted - before).max(axis=2)
    inside = _band(difference, (0.28, 0.32), (0.3, 0.7))
    far = _band(difference, (0.6, 1.0), (0.0, 1.0))
    assert inside.mean() > 10, "the stroke did not change the preview under it"
    assert far.max() == 0, "the stroke changed the preview far from it"

    page.click("#undo")
    _wait_until_shown(page)
    assert np.array_equal(_preview(page), before)
    assert np.array_equal(_on_screen(page), before)

    # Repaint, then a second stroke at once, while the first one's preview renders: neither is lost.
    _drag(page, *stroke)
    _drag(page, (0.15, 0.8), (0.85, 0.8))
    _wait_until_shown(page)
    state = page.request.get("/api/state").json()
    saturation = next(p for p in state["params"] if p["name"] == "saturation")
    assert saturation["low"] == pytest.approx(0.0, abs=1e-6)
    repainted = _preview(page)
    assert np.array_equal(_on_screen(page), repainted)
    assert np.array_equal(_band(repainted, (0.0, 0.5), (0, 1)), _band(painted, (0.0, 0.5), (0, 1)))
    lower = np.abs(repainted - before).max(axis=2)
    assert _band(lower, (0.78, 0.82), (0.3, 0.7)).mean() > 10, "the second stroke was lost"

    page.check("#overlay")
    page.wait_for_function(
        "() => document.getElementById('mask').dataset.shown"
        " === 'saturation@' + document.getElementById('status').dataset.target"
    )
    shot = tmp_path / "editor.png"
    page.screenshot(path=str(shot))
    if os.environ.get(SCREENSHOT_ENV):
        shutil.copyfile(shot, os.environ[SCREENSHOT_ENV])

    with page.expect_download() as saved:
        page.click("#save")
    params = tmp_path / "params.safetensors"
    saved.value.save_as(params)
    with page.expect_download(timeout=120_000) as exported:
        page.click("#export")
    export = tmp_path / "export.png"
    exported.value.save_as(export)
    context.close()

    applied = tmp_path / "applied.png"
    assert wise_main(["apply", "cartoon", str(photo), "--params", str(params), "-o", str(applied)]) == 0
    assert np.array_equal(np.asarray(Image.open(export)), np.asarray(Image.open(applied)))
    assert Image.open(export).size == (768, 768)
