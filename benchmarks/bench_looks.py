"""Measured looks on a portrait: oil paint strokes that follow the face, watercolor without dark
rims on it, and an XDoG sketch without filled blacks.

Usage::

    python benchmarks/bench_looks.py --portrait PORTRAIT [--photos P ...] [--crops OUT.png] [--json OUT.json]

Every picture is rendered at a 512-pixel short side. The face boxes are fractions of the
portrait's height and width (the NPRportrait photo of ``shared/data/portrait.png``, 819×1024):

- **Oil paint, mirror agreement**: the stroke orientation (structure tensor of the output,
  ``wise.metrics.orientation_agreement``) of ``effect(mirror(photo))`` against
  ``mirror(effect(photo))``, as mean ``cos(2Δθ)`` in the skin of both cheeks and the forehead.
  A flow taken from the picture commutes with the mirror (about 1); one fixed direction does not.
- **Watercolor, dark pixels in the face**: the share of the face ellipse's pixels whose
  luminance ends at least 0.12 below that of the photo blurred by 2 pixels (the photo itself
  against its own blur: the baseline of eyes and lashes).
- **Watercolor, pale blotches in the face**: the share of the face ellipse's pixels whose chroma
  (CIE C*ab, averaged over 5 pixels) lies more than 6 below that of their surroundings (a Gaussian
  of 12 pixels): highlights that lost the skin's hue (the photo's own freckles and highlights
  are the baseline).
- **XDoG sketch**: the share of dark pixels (luminance below 0.5) and the darkest 32-pixel block.
"""

from __future__ import annotations

import wise  # before torch, as the command line: OpenMP waits without spinning

# isort: split
import argparse
import json
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image
from scipy import ndimage
from skimage import color, data

from wise.filters import gaussian_blur
from wise.io import image_to_tensor, read_image, tensor_to_image
from wise.metrics import orientation_agreement

SHORT_SIDE = 512
SKIN_BOXES = {
    "left cheek": (0.40, 0.50, 0.29, 0.39),
    "right cheek": (0.40, 0.50, 0.58, 0.67),
    "forehead": (0.325, 0.35, 0.34, 0.61),
}
"""(top, bottom, left, right) as fractions of the portrait's height and width."""
FACE_ELLIPSE = (0.285, 0.665, 0.265, 0.71)
"""(top, bottom, left, right) of the ellipse around the face, hairline to chin."""
CROP_BOX = (0.27, 0.70, 0.22, 0.75)
"""The face at 100 % for the before/after pictures."""
DARKER_BY = 0.12
PHOTO_BLUR = 2.0
CHROMA_DIP = 6.0
CHROMA_LOCAL = 5
CHROMA_SURROUNDINGS = 12.0
DARK_LUMINANCE = 0.5
BLOCK = 32


def resized(image: torch.Tensor, short_side: int = SHORT_SIDE) -> torch.Tensor:
    height, width = image.shape[-2:]
    factor = short_side / min(height, width)
    return F.interpolate(image, size=(round(height * factor), round(width * factor)), mode="area")


def _box(image: torch.Tensor, box: tuple[float, float, float, float]) -> torch.Tensor:
    height, width = image.shape[-2:]
    top, bottom, left, right = box
    return image[..., round(top * height) : round(bottom * height), round(left * width) : round(right * width)]


def _render(effect: wise.effects.Effect, photo: torch.Tensor, preset: str) -> torch.Tensor:
    with torch.no_grad():
        return effect(photo, effect.preset(preset)[None])


def mirror_agreement(effect: wise.effects.Effect, photo: torch.Tensor, preset: str) -> dict[str, float]:
    mirrored = photo.flip(-1)
    agreement = orientation_agreement(_render(effect, mirrored, preset), _render(effect, photo, preset).flip(-1))
    agreement = agreement.flip(-1)  # back into the photo's frame, where the boxes are
    rows = {name: float(_box(agreement, box).mean()) for name, box in SKIN_BOXES.items()}
    rows["mean"] = sum(rows.values()) / len(SKIN_BOXES)
    return rows


def face_mask(image: torch.Tensor) -> torch.Tensor:
    height, width = image.shape[-2:]
    top, bottom, left, right = FACE_ELLIPSE
    ys = (torch.arange(height) + 0.5) / height
    xs = (torch.arange(width) + 0.5) / width
    cy, cx, ry, rx = (top + bottom) / 2, (left + right) / 2, (bottom - top) / 2, (right - left) / 2
    return ((ys[:, None] - cy) / ry) ** 2 + ((xs[None, :] - cx) / rx) ** 2 <= 1.0


def dark_share(result: torch.Tensor, photo: torch.Tensor) -> float:
    """Share of the face's pixels at least :data:`DARKER_BY` darker than the blurred photo."""
    blurred = gaussian_blur(photo.mean(dim=1, keepdim=True), PHOTO_BLUR, scale=1.0)
    darker = (blurred - result.mean(dim=1, keepdim=True))[0, 0] >= DARKER_BY
    return float(darker[face_mask(photo)].float().mean())


def pale_share(result: torch.Tensor, photo: torch.Tensor) -> float:
    """Share of the face's pixels whose chroma lies :data:`CHROMA_DIP` below their surroundings'."""
    lab = color.rgb2lab(result[0].clamp(0.0, 1.0).permute(1, 2, 0).double().numpy())
    chroma = np.hypot(lab[..., 1], lab[..., 2])
    dip = ndimage.uniform_filter(chroma, CHROMA_LOCAL) - ndimage.gaussian_filter(chroma, CHROMA_SURROUNDINGS)
    return float((dip[face_mask(photo).numpy()] < -CHROMA_DIP).mean())


def sketch_darkness(drawing: torch.Tensor) -> tuple[float, float]:
    """Share of dark pixels and the darkest :data:`BLOCK`-pixel block's share."""
    dark = (drawing.mean(dim=1, keepdim=True) < DARK_LUMINANCE).float()
    blocks = F.avg_pool2d(dark, BLOCK, stride=BLOCK // 2)
    return float(dark.mean()), float(blocks.max())


def crop_strip(portrait: torch.Tensor, rows: list[tuple[str, torch.Tensor]], out: Path) -> None:
    """One crop at 100 % per render, side by side, the photo first."""
    crops = [_box(portrait, CROP_BOX)] + [_box(image, CROP_BOX) for _, image in rows]
    height = min(c.shape[-2] for c in crops)
    strip = torch.cat([c[..., :height, :] for c in crops], dim=-1)
    Image.fromarray(tensor_to_image(strip)).save(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--portrait", type=Path, required=True)
    parser.add_argument("--photos", type=Path, nargs="*", default=[], help="more photos for the sketch check")
    parser.add_argument("--crops", type=Path, help="write the face crops of every oil paint and watercolor preset")
    parser.add_argument("--json", type=Path)
    parser.add_argument("--only", choices=("oilpaint", "watercolor", "sketch"), nargs="*", help="measure only these")
    args = parser.parse_args()

    portrait = resized(read_image(args.portrait))
    results: dict[str, dict] = {"oilpaint": {}, "watercolor": {}, "sketch": {}}
    renders: list[tuple[str, torch.Tensor]] = []

    only = set(args.only or ("oilpaint", "watercolor", "sketch"))
    oil = wise.effects.create("oilpaint").eval()
    print("| oil paint preset | " + " | ".join(SKIN_BOXES) + " | mean |")
    print("| --- |" + " --- |" * (len(SKIN_BOXES) + 1))
    for preset in oil.presets if "oilpaint" in only else ():
        rows = mirror_agreement(oil, portrait, preset)
        results["oilpaint"][preset] = rows
        renders.append((f"oilpaint {preset}", _render(oil, portrait, preset)))
        print(f"| {preset} | " + " | ".join(f"{v:.2f}" for v in rows.values()) + " |")

    water = wise.effects.create("watercolor").eval()
    baseline = {"darker": dark_share(portrait, portrait), "pale": pale_share(portrait, portrait)}
    results["watercolor"]["photo"] = baseline
    print(
        f"\n| watercolor preset | face pixels {DARKER_BY} darker | face pixels paler than their surroundings |"
        f"\n| --- | --- | --- |\n| (the photo) | {baseline['darker']:.2%} | {baseline['pale']:.2%} |"
    )
    for preset in water.presets if "watercolor" in only else ():
        result = _render(water, portrait, preset)
        renders.append((f"watercolor {preset}", result))
        rows = {"darker": dark_share(result, portrait), "pale": pale_share(result, portrait)}
        results["watercolor"][preset] = rows
        print(f"| {preset} | {rows['darker']:.2%} | {rows['pale']:.2%} |")

    xdog = wise.effects.create("xdog").eval()
    photos = {"portrait": portrait, "astronaut": resized(image_to_tensor(data.astronaut()))}
    photos.update({path.stem: resized(read_image(path)) for path in args.photos})
    print("\n| sketch on | dark pixels | darkest 32-px block |\n| --- | --- | --- |")
    for name, photo in photos.items() if "sketch" in only else ():
        dark, block = sketch_darkness(_render(xdog, photo, "sketch"))
        results["sketch"][name] = {"dark": dark, "darkest_block": block}
        print(f"| {name} | {dark:.1%} | {block:.0%} |")

    if args.crops:
        crop_strip(portrait, renders, args.crops)
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
