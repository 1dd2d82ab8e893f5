"""How long the editor takes to show an edit: a stroke, then the preview render, per effect.

Usage::

    python benchmarks/bench_editor.py [IMAGE] [--effects cartoon xdog] [--repeat 5]

The image (default ``skimage.data.astronaut()``, 512x512) is opened as in the editor, so
its preview has a 512-pixel short side (larger images are reduced, smaller ones kept).
Each repeat paints one stroke on the first parameter and renders the preview to PNG, as
the page's refresh does; the table gives the median and the slowest repeat.
"""

from __future__ import annotations

import argparse
import io
import statistics
import time
from pathlib import Path

import numpy as np
from PIL import Image
from skimage import data

from wise import effects
from wise.editor.session import EditorSession


def image_bytes(path: str | None) -> tuple[bytes, str]:
    if path is not None:
        return Path(path).read_bytes(), Path(path).name
    buffer = io.BytesIO()
    Image.fromarray(np.asarray(data.astronaut())).save(buffer, format="PNG")
    return buffer.getvalue(), "astronaut.png"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("image", nargs="?")
    parser.add_argument("--effects", nargs="+", default=effects.available())
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    content, name = image_bytes(args.image)
    print("| effect | preview | stroke | stroke + preview: median | slowest |")
    print("| --- | --- | --- | --- | --- |")
    for effect_name in args.effects:
        session = EditorSession()
        session.choose_effect(effect_name)
        session.open_image(content, name)
        session.render_preview(session.snapshot())  # warm-up
        param = session.effect.param_names[0]
        totals, strokes = [], []
        for k in range(args.repeat):
            start = time.perf_counter()
            y = 0.2 + 0.6 * k / max(1, args.repeat - 1)
            session.stroke(param, [(0.1, y), (0.9, y)], radius=0.05, hardness=0.5, mode="increase", amount=0.3)
            painted = time.perf_counter()
            session.render_preview(session.snapshot())
            totals.append(time.perf_counter() - start)
            strokes.append(painted - start)
        height, width = session.content.preview.shape[-2:]
        print(
            f"| {effect_name} | {width}x{height} | {statistics.median(strokes) * 1000:.0f} ms "
            f"| {statistics.median(totals):.2f} s | {max(totals):.2f} s |",
            flush=True,
        )


if __name__ == "__main__":
    main()
