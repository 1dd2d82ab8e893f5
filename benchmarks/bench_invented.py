"""Colours a re-creation invents: how far ``result.png`` of ``wise optimize`` / ``wise transfer``
strays from its ``target.png``.

Usage::

    python benchmarks/bench_invented.py RUN_FOLDER [RUN_FOLDER ...] [--size HxW]

Both pictures are reduced to ``--size`` (default: the result's size) and blurred by sigma 1 px;
then, in CIE Lab, the share of pixels more than 30 ΔE from the target's pixel (the issue's
measure), and the share more than 30 ΔE from every target pixel within 4 px: colours the
reference has nowhere near, as opposed to colours the effect could not reach.
"""

from __future__ import annotations

import wise  # noqa: F401  (before torch, as the command line: OpenMP waits without spinning)

# isort: split
import argparse
from pathlib import Path

import torch
import torch.nn.functional as F

from wise.filters import gaussian_blur, rgb_to_lab
from wise.io import read_image
from wise.metrics import FAR_COLOUR, far_colour_share

WINDOW = 9


def shares(result: torch.Tensor, target: torch.Tensor) -> tuple[float, float]:
    made, wanted = (rgb_to_lab(gaussian_blur(image, 1.0, scale=1.0)) for image in (result, target))
    pad = WINDOW // 2
    near = F.unfold(F.pad(wanted, (pad,) * 4, mode="replicate"), WINDOW).view(1, 3, WINDOW * WINDOW, *made.shape[-2:])
    nearest = (near - made[:, :, None]).norm(dim=1).min(dim=1).values
    return far_colour_share(result, target), float((nearest > FAR_COLOUR).float().mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", nargs="+", type=Path, help="folders with result.png and target.png")
    parser.add_argument("--size", help="HxW to compare at (default: the result's size)")
    args = parser.parse_args()
    print("| run | ΔE > 30 | invented (ΔE > 30 from every target pixel within 4 px) |")
    print("| --- | --- | --- |")
    for run in args.runs:
        result, target = read_image(run / "result.png"), read_image(run / "target.png")
        size = tuple(int(v) for v in args.size.split("x")) if args.size else tuple(result.shape[-2:])
        result = F.interpolate(result, size=size, mode="area")
        target = F.interpolate(target, size=size, mode="area")
        far, invented = shares(result, target)
        print(f"| {run.name} | {100 * far:.1f} % | {100 * invented:.1f} % |")


if __name__ == "__main__":
    main()
