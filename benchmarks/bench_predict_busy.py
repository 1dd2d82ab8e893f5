"""``wise predict`` on its default budget, on a quiet machine and beside busy processes.

Usage::

    python benchmarks/bench_predict_busy.py PHOTO [PHOTO ...] [--busy 2] [--rounds 2]
        [--effects xdog:portrait cartoon:bold]

Makes each example with ``wise apply EFFECT --preset PRESET`` from each PHOTO (at a 512-pixel
short side), then runs the whole command ``wise predict`` on it, quiet and while ``--busy`` other
processes keep a core busy each, alternating for ``--rounds`` rounds, and prints for each run the
refinement's seconds, its descent iterations, what it left out and the SSIM of the result, then
each effect's mean SSIM quiet and busy and their difference.
"""

from __future__ import annotations

import argparse
import json
import statistics
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
    parser.add_argument("photos", type=Path, nargs="+")
    parser.add_argument("--busy", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--effects", nargs="+", default=["xdog:portrait", "cartoon:bold"], metavar="EFFECT:PRESET")
    args = parser.parse_args()
    means: dict[tuple[str, bool], list[float]] = {}
    with tempfile.TemporaryDirectory() as folder:
        work = Path(folder)
        print("| effect | photo | machine | refinement | iterations | left out | SSIM |")
        print("| --- | --- | --- | --- | --- | --- | --- |")
        for number, source in enumerate(args.photos):
            image = Image.open(source).convert("RGB")
            factor = 512 / min(image.size)
            photo = work / f"photo{number}.png"
            image.resize((round(image.width * factor), round(image.height * factor)), Image.LANCZOS).save(photo)
            for look in args.effects:
                effect, preset = look.split(":")
                example = work / f"{effect}{number}.png"
                subprocess.run([*WISE, "apply", effect, "--preset", preset, str(photo), "-o", str(example)],
                               check=True, capture_output=True)  # fmt: skip
                for round_ in range(args.rounds):
                    for loaded in (False, True):
                        out = work / f"{effect}-{number}-{round_}-{loaded}"
                        if loaded:
                            with busy(args.busy):
                                scores = predicted(photo, example, out, effect)
                        else:
                            scores = predicted(photo, example, out, effect)
                        refined = scores["refinement"]
                        means.setdefault((look, loaded), []).append(scores["ssim"])
                        print(
                            f"| {look} | {source.stem} | {'busy' if loaded else 'quiet'} | "
                            f"{refined['seconds']:.1f} s | "
                            f"{refined['iterations']} | {', '.join(refined.get('left_out', [])) or '-'} | "
                            f"{scores['ssim']:.4f} |",
                            flush=True,
                        )
    print("\n| effect | quiet SSIM | busy SSIM | busy - quiet |")
    print("| --- | --- | --- | --- |")
    for look in args.effects:
        quiet, loaded = (statistics.mean(means[look, state]) for state in (False, True))
        print(f"| {look} | {quiet:.4f} | {loaded:.4f} | {loaded - quiet:+.4f} |")


if __name__ == "__main__":
    main()
