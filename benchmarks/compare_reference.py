"""SSIM of our XDoG against the public reference implementation's outputs.

Usage::

    python benchmarks/compare_reference.py DATA_DIR

``DATA_DIR`` holds ``portrait.png`` and ``reference/astronaut.png`` with the reference
outputs ``reference/xdog_<photo>_<preset>.png`` (rendered by the reference code at full
resolution). Prints one line per photo and preset; SSIM on the grey output at full size.
The reference's preset values are passed explicitly (the project's own presets serve users
and may differ; ``tests/effects/reference_xdog.py`` holds the same values).
"""

from __future__ import annotations

import wise  # before torch, as the command line: OpenMP waits without spinning

# isort: split
import argparse
from pathlib import Path

import numpy as np
import torch
from PIL import Image
from skimage.metrics import structural_similarity

from wise.io import read_image

REFERENCE_PRESETS = {
    "portrait": {
        "brightness": 0.1,
        "contrast": 1.15,
        "saturation": 1.02,
        "details": 2.27,
        "stroke_width": 0.54,
        "contour": 1.0,
        "blackness": 0.15,
        "shading": 0.0,
    },
    "sketch": {
        "brightness": 0.1,
        "contrast": 1.0,
        "saturation": 0.0,
        "details": 1.3,
        "stroke_width": 0.2,
        "contour": 3.0,
        "blackness": 0.5,
        "shading": 0.0,
    },
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("data", type=Path)
    args = parser.parse_args()
    photos = {"portrait": args.data / "portrait.png", "astronaut": args.data / "reference" / "astronaut.png"}
    effect = wise.effects.create("xdog")
    print("| photo | size | preset | SSIM |")
    print("| --- | --- | --- | --- |")
    for photo, path in photos.items():
        image = read_image(path)
        for preset, values in REFERENCE_PRESETS.items():
            with torch.no_grad():
                ours = effect(image, effect.params_from_dict(values)[None])
            ours_u8 = (ours[0, 0].clamp(0, 1) * 255).round().to(torch.uint8).numpy()
            reference = np.asarray(Image.open(args.data / "reference" / f"xdog_{photo}_{preset}.png").convert("L"))
            score = structural_similarity(ours_u8, reference, data_range=255)
            print(f"| {photo} | {image.shape[-1]}×{image.shape[-2]} | {preset} | {score:.3f} |")


if __name__ == "__main__":
    main()
