"""The same look at any size: every preset of every effect rendered at a small size against its
reference-size render reduced to that size.

Usage::

    python benchmarks/bench_sizes.py PHOTO [PHOTO ...] [--size 256] [--json OUT.json]

Each photo is reduced to a 512-pixel short side (the reference) and to ``--size``. Both are
rendered as ``wise apply`` renders them (``wise.render.render``); the reference render is then
reduced to ``--size`` and compared with the small render: SSIM on the luminance, and for XDoG
the ink (share of pixels darker than 0.5) of the small render over that of the reduced one.
``--own-scale`` renders the small picture at its own scale instead, as ``wise`` did before.
"""

from __future__ import annotations

import wise  # before torch, as the command line: OpenMP waits without spinning

# isort: split
import argparse
import json
from pathlib import Path

import numpy as np
import torch
from skimage.metrics import structural_similarity

from wise.filters._checks import REFERENCE_SHORT_SIDE
from wise.io import read_image, tensor_to_image
from wise.render import reduced, render

INK_LUMINANCE = 0.5


def resized(image: torch.Tensor, short_side: int) -> torch.Tensor:
    height, width = image.shape[-2:]
    factor = short_side / min(height, width)
    return reduced(image, (round(height * factor), round(width * factor)))


def luminance(image: torch.Tensor) -> np.ndarray:
    return tensor_to_image(image).astype(np.float64).mean(axis=-1) / 255.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("photos", nargs="+", type=Path)
    parser.add_argument("--size", type=int, default=256, help="short side of the small render (default 256)")
    parser.add_argument("--own-scale", action="store_true", help="render the small picture at its own scale")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    results: dict[str, dict[str, dict[str, float]]] = {}
    print("| photo | effect | preset | SSIM | ink ratio |\n| --- | --- | --- | --- | --- |")
    for path in args.photos:
        reference_photo = resized(read_image(path), REFERENCE_SHORT_SIDE)
        small_photo = resized(reference_photo, args.size)
        for name in wise.effects.available():
            effect = wise.effects.create(name).eval()
            for preset in effect.presets:
                params = effect.preset(preset)[None]
                reference = reduced(render(effect, reference_photo, params), tuple(small_photo.shape[-2:]))
                if args.own_scale:
                    with torch.no_grad():
                        small = effect(small_photo, params).clamp(0.0, 1.0)
                else:
                    small = render(effect, small_photo, params)
                a, b = luminance(small), luminance(reference)
                row = {"ssim": float(structural_similarity(a, b, data_range=1.0))}
                if name == "xdog":
                    row["ink_ratio"] = float((a < INK_LUMINANCE).mean() / max((b < INK_LUMINANCE).mean(), 1e-9))
                results.setdefault(path.stem, {})[f"{name}/{preset}"] = row
                ink = f"{row['ink_ratio']:.2f}" if "ink_ratio" in row else ""
                print(f"| {path.stem} | {name} | {preset} | {row['ssim']:.3f} | {ink} |", flush=True)
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=1))
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
