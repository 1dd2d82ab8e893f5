"""``wise predict`` on its default budget, on a quiet machine and beside busy processes.

Usage::

    python benchmarks/bench_predict_busy.py PHOTO [--busy 2] [--rounds 2] [--effects xdog:portrait cartoon:bold]

Makes each example with ``wise apply EFFECT --preset PRESET`` from PHOTO (at a 512-pixel short
side), then runs the whole command ``wise predict`` on it, quiet and while ``--busy`` other
processes keep a core busy each, alternating for ``--rounds`` rounds, and prints for each run the
refinement's seconds, its descent iterations, what it left out and the SSIM of the result.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from bench_busy import busy
from PIL import Image

WISE = [sys.executable, "-m", "wise"]


def predicted(photo: Path, example: Path, folder: Path, effect: str) -> dict:
    subprocess.run([*WISE, "predict", effect, "--content", str(photo), "--target", str(example), "-o", str(folder)],
                   check=True, capture_output=True)  # fmt: skip
    return json.loads((folder / "metrics.json").read_text())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("photo", type=Path)
    parser.add_argument("--busy", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--effects", nargs="+", default=["xdog:portrait", "cartoon:bold"], metavar="EFFECT:PRESET")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        work = Path(folder)
        image = Image.open(args.photo).convert("RGB")
        factor = 512 / min(image.size)
        photo = work / "photo.png"
        image.resize((round(image.width * factor), round(image.height * factor)), Image.LANCZOS).save(photo)
        print("| effect | machine | refinement | iterations | left out | SSIM |")
        print("| --- | --- | --- | --- | --- | --- |")
        for look in args.effects:
            effect, preset = look.split(":")
            example = work / f"{effect}.png"
            subprocess.run([*WISE, "apply", effect, "--preset", preset, str(photo), "-o", str(example)], check=True)
            for round_ in range(args.rounds):
                for loaded in (False, True):
                    out = work / f"{effect}-{round_}-{loaded}"
                    if loaded:
                        with busy(args.busy):
                            scores = predicted(photo, example, out, effect)
                    else:
                        scores = predicted(photo, example, out, effect)
                    refined = scores["refinement"]
                    print(
                        f"| {look} | {'busy' if loaded else 'quiet'} | {refined['seconds']:.1f} s | "
                        f"{refined['iterations']} | {', '.join(refined.get('left_out', [])) or '-'} | "
                        f"{scores['ssim']:.4f} |",
                        flush=True,
                    )


if __name__ == "__main__":
    main()
