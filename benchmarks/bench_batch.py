"""Images per second of ``wise apply`` over a folder: a shell loop of single commands against
one process (``--workers``) and ``--ray`` with a local instance, on the same photos.

Usage::

    python benchmarks/bench_batch.py [--count 20] [--size 1024] [--effect xdog] [--ray]

Makes ``--count`` photos of ``--size`` px (crops and flips of skimage's astronaut, coffee and
chelsea, enlarged) in a temporary folder, then times each way of stylizing them into a fresh
output folder, every one a new process as a user would run it. Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from PIL import Image
from skimage import data


def make_photos(folder: Path, count: int, size: int) -> list[Path]:
    sources = [data.astronaut(), data.coffee(), data.chelsea()]
    paths = []
    for i in range(count):
        picture = Image.fromarray(sources[i % len(sources)])
        width, height = picture.size
        box = (i % 5 * width // 20, i % 4 * height // 20, width - i % 3 * width // 20, height)
        picture = picture.crop(box)
        if i % 2:
            picture = picture.transpose(Image.Transpose.FLIP_LEFT_RIGHT)
        picture = picture.resize((size, size * picture.size[1] // picture.size[0]), Image.Resampling.BICUBIC)
        path = folder / f"photo-{i:03d}.jpg"
        picture.save(path, quality=92)
        paths.append(path)
    return paths


def timed(command: list[str]) -> float:
    began = time.perf_counter()
    subprocess.run(command, check=True, capture_output=True)
    return time.perf_counter() - began


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--count", type=int, default=20)
    parser.add_argument("--size", type=int, default=1024)
    parser.add_argument("--effect", default="xdog")
    parser.add_argument("--ray", action="store_true", help="also time --ray with a local instance")
    args = parser.parse_args()
    wise = [sys.executable, "-m", "wise", "apply", args.effect]
    with tempfile.TemporaryDirectory() as scratch:
        root = Path(scratch)
        photos = root / "photos"
        photos.mkdir()
        paths = make_photos(photos, args.count, args.size)
        subprocess.run([*wise, str(paths[0]), "-o", str(root / "warm.png")], check=True)  # kernels compiled
        rows = []
        loop = root / "loop"
        loop.mkdir()
        began = time.perf_counter()
        for path in paths:
            subprocess.run([*wise, str(path), "-o", str(loop / f"{path.stem}.png")], check=True, capture_output=True)
        rows.append(("a shell loop of single `wise apply`", time.perf_counter() - began))
        for workers in (1, 2):
            seconds = timed([*wise, str(photos), "-o", str(root / f"workers-{workers}"), "--workers", str(workers)])
            rows.append((f"one process, `--workers {workers}`", seconds))
        if args.ray:
            rows.append(("`--ray`, local instance", timed([*wise, str(photos), "-o", str(root / "ray"), "--ray"])))
    base = rows[0][1]
    print(f"{args.count} photos of {args.size} px, {args.effect}\n")
    print("| how | seconds | images/s | speed-up |\n| --- | --- | --- | --- |")
    for name, seconds in rows:
        print(f"| {name} | {seconds:.1f} | {args.count / seconds:.2f} | ×{base / seconds:.2f} |")


if __name__ == "__main__":
    main()
