"""Every preset of every effect on two faces, measured as a painter would look at them.

Usage::

    python benchmarks/bench_faces.py [--portrait PORTRAIT] [--effects E ...] [--crops DIR] [--json OUT.json]

Each picture is rendered as ``wise apply`` renders it (``wise.render.render`` at the picture's
own size): ``skimage.data.astronaut()`` (512×512, face x 165–285, y 40–175) and, when
``--portrait`` names it, the NPRportrait photo of ``shared/data/portrait.png`` (819×1024, face
x 250–580, y 300–650). Three measures on the face box, on CIE L*:

- **blown**: the share of the face's pixels that end above L* 95 where the photo is below 88
  (skin washed to white by highlights);
- **L* shift**: mean L* of the render minus that of the photo (a brighter or darker face);
- **feature contrast**: the photo's darkest 5 % of the face (eyes, brows, nostrils, the line
  of the lips); both images blurred by sigma 1 px; the face's median minus the mean of those
  pixels, render over photo. 1: the features are as defined as in the photo.

``--crops DIR`` writes each face at 100 %, the photo first, one strip per effect.
"""

from __future__ import annotations

import wise  # before torch, as the command line: OpenMP waits without spinning

# isort: split
import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch
from PIL import Image
from skimage import data

from wise.io import image_to_tensor, read_image, tensor_to_image
from wise.metrics import face_measures
from wise.render import render

FACES = {
    "astronaut": (40, 175, 165, 285),
    "portrait": (300, 650, 250, 580),
}
"""(top, bottom, left, right) of the face in the photo's own pixels."""


def render_preset(effect: wise.effects.Effect, photo: torch.Tensor, preset: str) -> np.ndarray:
    return tensor_to_image(render(effect, photo, effect.preset(preset)[None]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--portrait", type=Path, help="the 819×1024 NPRportrait photo (shared/data/portrait.png)")
    parser.add_argument("--effects", nargs="*", default=wise.effects.available(), help="effects to measure")
    parser.add_argument("--presets", nargs="*", help="only these presets")
    parser.add_argument("--crops", type=Path, help="folder for the face crops at 100 %%")
    parser.add_argument("--json", type=Path, help="write the figures as JSON")
    args = parser.parse_args()

    photos = {"astronaut": image_to_tensor(data.astronaut())}
    if args.portrait is not None:
        photos["portrait"] = read_image(args.portrait)
    if args.crops is not None:
        args.crops.mkdir(parents=True, exist_ok=True)
    results: dict[str, dict[str, dict[str, dict[str, float]]]] = {}
    names = list(photos)
    print("| effect | preset | " + " | ".join(f"{n} blown | {n} L* shift | {n} contrast" for n in names) + " |")
    print("| --- | --- |" + " --- | --- | --- |" * len(names))
    for effect_name in args.effects:
        effect = wise.effects.create(effect_name).eval()
        crops = {name: [tensor_to_image(photo)] for name, photo in photos.items()}
        for preset in effect.presets:
            if args.presets and preset not in args.presets:
                continue
            started = time.perf_counter()
            row = {}
            for name, photo in photos.items():
                rendered = render_preset(effect, photo, preset)
                row[name] = face_measures(rendered, tensor_to_image(photo), FACES[name])
                crops[name].append(rendered)
            results.setdefault(effect_name, {})[preset] = row
            cells = " | ".join(f"{m['blown']:.1%} | {m['shift']:+.1f} | {m['contrast']:.2f}" for m in row.values())
            print(f"| {effect_name} | {preset} | {cells} |  ({time.perf_counter() - started:.0f} s)", flush=True)
        if args.crops is not None:
            for name, images in crops.items():
                top, bottom, left, right = FACES[name]
                strip = np.concatenate([image[top:bottom, left:right] for image in images], axis=1)
                path = args.crops / f"{effect_name}_{name}.png"
                Image.fromarray(strip).save(path)
                print(f"wrote {path}")
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=1))
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
