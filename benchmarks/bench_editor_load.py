"""The editor under load: several browsers painting at once against the real server.

Usage::

    python benchmarks/bench_editor_load.py [--sessions 8] [--strokes 50] [--effect xdog] [--size 512] [--quick]

Starts the editor (uvicorn in a subprocess, as ``wise edit`` does) on the astronaut at
``--size`` pixels square. Each session is a thread with its own cookie that sends its strokes,
each followed by a preview request (``--quick``: the quick preview first, as the page now
asks). Every request must succeed; then each session's saved masks (``/api/params.safetensors``)
must equal those of its strokes replayed alone in a fresh in-process session, so sessions
neither lose edits nor see each other's.
Prints the latency of strokes and previews (median, 95th percentile), requests per second and
the total time as a markdown table.
"""

from __future__ import annotations

import wise  # noqa: F401  (before torch, as the command line: OpenMP waits without spinning)

# isort: split
import argparse
import math
import random
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import torch
from PIL import Image
from safetensors.torch import load as load_safetensors
from skimage import data

from wise.editor.server import initial_session

LAUNCH = (
    "import sys; from wise.editor.server import initial_session, serve; "
    "serve(initial_session(sys.argv[1], effect=sys.argv[4]), sys.argv[2], int(sys.argv[3]))"
)
START_SECONDS = 60
TOLERANCE = 1e-6
"""Largest difference allowed between served and replayed masks (normally they are equal)."""


@dataclass
class Browser:
    """One session's strokes, latencies and errors."""

    strokes: list[dict]
    stroke_seconds: list[float] = field(default_factory=list)
    preview_seconds: list[float] = field(default_factory=list)
    quick_seconds: list[float] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)
    saved: bytes = b""


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


DRAG_STEP = (0.005, 0.03)
"""Distance between a drag's successive points (fractions of the image), as a mouse reports them."""


def drag(rng: random.Random, count: int) -> list[list[float]]:
    """A brush drag of ``count`` points: a walk from a random place that turns gradually."""
    x, y, heading = rng.random(), rng.random(), rng.uniform(0.0, 2.0 * math.pi)
    points = [[x, y]]
    for _ in range(count - 1):
        heading += rng.gauss(0.0, 0.4)
        step = rng.uniform(*DRAG_STEP)
        x = min(1.0, max(0.0, x + step * math.cos(heading)))
        y = min(1.0, max(0.0, y + step * math.sin(heading)))
        points.append([x, y])
    return points


def make_strokes(
    seed: int, count: int, names: list[str], ranges: list[tuple[float, float]], scattered: bool = False
) -> list[dict]:
    """``count`` varied strokes: any parameter, mode, size, place; each a drag of up to 40 points
    (``scattered``: points anywhere in the image, every stroke spanning most of it)."""
    rng = random.Random(seed)
    strokes = []
    for _ in range(count):
        index = rng.randrange(len(names))
        low, high = ranges[index]
        length = rng.randint(1, 40)
        points = [[rng.random(), rng.random()] for _ in range(length)] if scattered else drag(rng, length)
        stroke = {"param": names[index], "points": points, "radius": rng.uniform(0.02, 0.2)}
        stroke.update(hardness=rng.random(), mode=rng.choice(["increase", "decrease", "set"]))
        stroke.update(amount=rng.uniform(0.05, 1.0), value=rng.uniform(low, high))
        strokes.append(stroke)
    return strokes


def paint(url: str, browser: Browser, start: threading.Barrier, quick: bool = False) -> None:
    """The session's strokes, each followed by the page's preview requests (``quick``: the quick
    preview, then the full one)."""
    requests = [("/api/stroke", browser.stroke_seconds)]
    if quick:
        requests.append(("/api/preview?quick=1", browser.quick_seconds))
    requests.append(("/api/preview", browser.preview_seconds))
    with httpx.Client(base_url=url, timeout=300) as client:
        if client.get("/api/state").status_code != 200:
            browser.errors.append("no session")
            return
        start.wait()
        for stroke in browser.strokes:
            for path, seconds in requests:
                began = time.perf_counter()
                try:
                    response = client.post(path, json=stroke) if path == "/api/stroke" else client.get(path)
                except httpx.HTTPError as e:
                    browser.errors.append(f"{path}: {type(e).__name__}")
                    continue
                seconds.append(time.perf_counter() - began)
                if response.status_code != 200:
                    browser.errors.append(f"{path}: {response.status_code} {response.text[:200]}")
        browser.saved = client.get("/api/params.safetensors").content


def replayed_masks(photo: Path, effect: str, strokes: list[dict]) -> torch.Tensor:
    session = initial_session(str(photo), effect=effect).copy()
    for s in strokes:
        session.stroke(s["param"], s["points"], s["radius"], s["hardness"], s["mode"], s["amount"], s["value"])
    return load_safetensors(session.params_file())["params"]


def start_server(photo: Path, port: int, effect: str) -> subprocess.Popen:
    command = [sys.executable, "-c", LAUNCH, str(photo), "127.0.0.1", str(port), effect]
    server = subprocess.Popen(command, stdout=subprocess.DEVNULL)
    deadline = time.monotonic() + START_SECONDS
    while True:
        try:
            httpx.get(f"http://127.0.0.1:{port}/static/editor.css", timeout=2)
            return server
        except httpx.TransportError:
            if server.poll() is not None or time.monotonic() > deadline:
                server.kill()
                raise SystemExit("the editor did not start") from None
            time.sleep(0.2)


def percentile(values: list[float], fraction: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(fraction * (len(ordered) - 1)))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sessions", type=int, default=8)
    parser.add_argument("--strokes", type=int, default=50)
    parser.add_argument("--effect", default="xdog")
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument(
        "--quick", action="store_true", help="each stroke's quick preview before the full one, as the page asks"
    )
    parser.add_argument(
        "--scattered", action="store_true", help="strokes of points scattered over the whole image instead of drags"
    )
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as folder:
        photo = Path(folder) / "astronaut.png"
        Image.fromarray(data.astronaut()).resize((args.size, args.size), Image.Resampling.LANCZOS).save(photo)
        template = initial_session(str(photo), effect=args.effect)
        names = template.effect.param_names
        ranges = [(spec.min, spec.max) for spec in template.effect.param_specs]
        browsers = [Browser(make_strokes(k, args.strokes, names, ranges, args.scattered)) for k in range(args.sessions)]
        port = free_port()
        server = start_server(photo, port, args.effect)
        try:
            start = threading.Barrier(args.sessions + 1)
            url = f"http://127.0.0.1:{port}"
            threads = [threading.Thread(target=paint, args=(url, b, start, args.quick)) for b in browsers]
            for thread in threads:
                thread.start()
            start.wait()
            began = time.perf_counter()
            for thread in threads:
                thread.join()
            total = time.perf_counter() - began
        finally:
            server.terminate()
            server.wait(timeout=30)

        errors = [e for b in browsers for e in b.errors]
        assert not errors, f"{len(errors)} failed requests, e.g. {errors[:3]}"
        worst = 0.0
        for k, browser in enumerate(browsers):
            served = load_safetensors(browser.saved)["params"]
            alone = replayed_masks(photo, args.effect, browser.strokes)
            assert not torch.equal(served, load_safetensors(template.params_file())["params"]), "nothing painted"
            worst = max(worst, float((served - alone).abs().max()))
            assert worst <= TOLERANCE, f"session {k}: its masks differ from its strokes replayed alone by {worst}"

    strokes = [t for b in browsers for t in b.stroke_seconds]
    previews = [t for b in browsers for t in b.preview_seconds]
    both = [a + b for browser in browsers for a, b in zip(browser.stroke_seconds, browser.preview_seconds)]
    quick = [t for b in browsers for t in b.quick_seconds]
    first = [a + b for browser in browsers for a, b in zip(browser.stroke_seconds, browser.quick_seconds)]
    requests = len(strokes) + len(previews) + len(quick)
    print(f"{args.sessions} sessions x {args.strokes} strokes + previews, {args.effect}, {args.size}x{args.size}")
    print()
    print("| request | count | median | 95th percentile |")
    print("| --- | --- | --- | --- |")
    rows = [("stroke", strokes), ("preview", previews), ("stroke + preview", both)]
    if quick:
        rows += [("quick preview", quick), ("stroke + quick preview (first visible)", first)]
    for name, seconds in rows:
        print(
            f"| {name} | {len(seconds)} | {statistics.median(seconds) * 1000:.0f} ms "
            f"| {percentile(seconds, 0.95) * 1000:.0f} ms |"
        )
    print()
    print(
        f"{requests} requests in {total:.1f} s: {requests / total:.1f} requests/s, 0 errors; "
        f"masks equal to each session replayed alone (largest difference {worst:g})"
    )


if __name__ == "__main__":
    main()
