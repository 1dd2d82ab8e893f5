"""How soon a brush stroke shows in the editor, one user: the stroke's request and the quick
preview after it (what the page shows first), then the full preview.

Usage::

    python benchmarks/bench_editor_stroke.py PHOTO [--strokes 10] [--effects ...]

Runs the editor's app in process (no network), opens PHOTO, and for each effect paints
``--strokes`` strokes of brightness at different places, each followed by the quick and the
full preview, as the page asks for them. Reports the median and the largest time per effect.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from fastapi.testclient import TestClient

import wise
from wise.editor.app import create_app
from wise.editor.session import EditorSession


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("photo", type=Path)
    parser.add_argument("--strokes", type=int, default=10)
    parser.add_argument("--effects", nargs="+", default=wise.effects.available())
    args = parser.parse_args()
    print("| effect | stroke + quick preview: median / max | full preview: median / max |")
    print("| --- | --- | --- |")
    for name in args.effects:
        client = TestClient(create_app(EditorSession()), base_url="http://localhost")
        assert client.post("/api/effect", json={"effect": name}).status_code == 200
        opened = client.post("/api/image", content=args.photo.read_bytes(), headers={"X-File-Name": args.photo.name})
        assert opened.status_code == 200, opened.text
        client.get("/api/preview?quick=1"), client.get("/api/preview")  # first renders: caches and kernels
        first, full = [], []
        for index in range(args.strokes):
            y = 0.1 + 0.8 * index / max(1, args.strokes - 1)
            stroke = {"param": "brightness", "points": [[0.2, y], [0.6, y]], "radius": 0.05, "hardness": 1.0}
            began = time.perf_counter()
            assert client.post("/api/stroke", json={**stroke, "mode": "set", "value": 0.2}).status_code == 200
            assert client.get("/api/preview?quick=1").status_code == 200
            first.append(time.perf_counter() - began)
            began = time.perf_counter()
            assert client.get("/api/preview").status_code == 200
            full.append(time.perf_counter() - began)
        print(
            f"| {name} | {statistics.median(first):.3f} / {max(first):.3f} s "
            f"| {statistics.median(full):.3f} / {max(full):.3f} s |",
            flush=True,
        )


if __name__ == "__main__":
    main()
