"""How much of the medium shows: each preset of oil paint and watercolor against its photo, and
how far each parameter of every effect moves the picture.

Usage::

    python benchmarks/bench_medium.py PHOTO [PHOTO ...] [--sizes 256 1024] [--effects oilpaint watercolor]
        [--json OUT.json] [--sheet OUT.png] [--params]

Each photo is reduced (area) to each short side and rendered with each preset of each effect as
``wise apply`` renders it (:func:`wise.render.render`). Per render:

- **SSIM to the photo**: grey-level SSIM (scikit-image, Gaussian window, data range 1) of the
  render's luminance against the photo's. A render that reads as the photo scores 0.9 or more.
- **Added texture**: in the photo's flattest 40 % (lowest local deviation of L* over
  :data:`FLAT_SIGMA` pixels), the mean local deviation of the render's L* over
  :data:`TEXTURE_SIGMA` pixels minus the photo's: the strokes, relief, pigment and paper that
  show at 100 %, in L* units.

``--sheet`` writes the renders of the first photo, one row per size (reduced to the smallest
size's height for the overview), each preset a column. ``--params`` also prints, for every
parameter of every effect, the change of the picture from the parameter's minimum to its maximum
with the others mid-range on a 256-pixel crop of the first photo: the mean absolute change and its
99th percentile (a slider that does nothing visible moves neither).
"""

from __future__ import annotations

import wise  # noqa: F401 (before torch, as the command line: OpenMP waits without spinning)

# isort: split
import argparse
import json
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from skimage.metrics import structural_similarity

from wise import effects
from wise.filters import gaussian_blur, rgb_to_lab
from wise.io import read_image, write_image
from wise.render import render

FLAT_SHARE = 0.4
FLAT_SIGMA = 4.0
TEXTURE_SIGMA = 2.0
PARAM_SIDE = 256


def resized(image: torch.Tensor, short_side: int) -> torch.Tensor:
    height, width = image.shape[-2:]
    factor = short_side / min(height, width)
    size = (round(height * factor), round(width * factor))
    return F.interpolate(image, size=size, mode="area" if factor < 1 else "bicubic").clamp(0.0, 1.0)


def luminance(image: torch.Tensor) -> np.ndarray:
    weights = torch.tensor([0.299, 0.587, 0.114]).view(1, 3, 1, 1)
    return (image * weights).sum(dim=1)[0].numpy()


def local_deviation(lightness: torch.Tensor, sigma: float) -> torch.Tensor:
    mean = gaussian_blur(lightness, sigma)
    return (gaussian_blur(lightness * lightness, sigma) - mean * mean).clamp_min(0.0).sqrt()


def added_texture(photo: torch.Tensor, rendered: torch.Tensor) -> float:
    photo_l, render_l = rgb_to_lab(photo)[:, :1], rgb_to_lab(rendered)[:, :1]
    flatness = local_deviation(photo_l, FLAT_SIGMA).flatten()
    flat = flatness <= torch.quantile(flatness, FLAT_SHARE)
    photo_texture = local_deviation(photo_l, TEXTURE_SIGMA).flatten()[flat]
    render_texture = local_deviation(render_l, TEXTURE_SIGMA).flatten()[flat]
    return float((render_texture - photo_texture).mean())


def grey_ssim(photo: torch.Tensor, rendered: torch.Tensor) -> float:
    return float(
        structural_similarity(luminance(photo), luminance(rendered), data_range=1.0, gaussian_weights=True, sigma=1.5)
    )


def measure(photos: list[Path], sizes: list[int], names: list[str]) -> tuple[list[dict], dict]:
    rows, sheet = [], {}
    for index, path in enumerate(photos):
        original = read_image(path)
        for size in sizes:
            photo = resized(original, size)
            for name in names:
                effect = effects.create(name).eval()
                for preset in effect.presets:
                    with torch.no_grad():
                        rendered = render(effect, photo, effect.preset(preset)[None]).clamp(0.0, 1.0)
                    row = {
                        "photo": path.name,
                        "size": size,
                        "look": f"{name}:{preset}",
                        "ssim": round(grey_ssim(photo, rendered), 4),
                        "texture": round(added_texture(photo, rendered), 2),
                    }
                    rows.append(row)
                    print(f"| {row['photo']} | {size} | {row['look']} | {row['ssim']:.4f} | {row['texture']:+.2f} |")
                    if index == 0:
                        sheet[(size, row["look"])] = rendered
    return rows, sheet


def write_sheet(sheet: dict, sizes: list[int], path: Path) -> None:
    looks = list(dict.fromkeys(look for _, look in sheet))
    height = min(image.shape[-2] for image in sheet.values())
    rows = []
    for size in sizes:
        cells = [resized(sheet[(size, look)], height) for look in looks]
        rows.append(torch.cat(cells, dim=-1))
    write_image(torch.cat(rows, dim=-2), path)
    print(f"wrote {path} (columns: {', '.join(looks)}; rows: {', '.join(map(str, sizes))} px)")


def parameter_reach(photo: Path) -> list[dict]:
    image = resized(read_image(photo), PARAM_SIDE)
    rows = []
    for name in effects.available():
        effect = effects.create(name).eval()
        for position, spec in enumerate(effect.param_specs):
            renders = []
            for end in (-0.5, 0.5):
                params = torch.zeros(1, len(effect.param_specs))
                params[0, position] = end
                with torch.no_grad():
                    renders.append(render(effect, image, params).clamp(0.0, 1.0))
            change = (renders[1] - renders[0]).abs()
            row = {
                "effect": name,
                "parameter": spec.name,
                "mean": float(change.mean()),
                "p99": float(torch.quantile(change.flatten(), 0.99)),
            }
            rows.append(row)
            visible = row["mean"] >= 2e-3 or row["p99"] >= 5 / 255
            shown = "yes" if visible else "NO"
            print(f"| {name} | {spec.name} | {row['mean']:.4f} | {row['p99'] * 255:.1f}/255 | {shown} |")
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("photos", nargs="+", type=Path)
    parser.add_argument("--sizes", nargs="+", type=int, default=[256, 1024])
    parser.add_argument("--effects", nargs="+", default=["oilpaint", "watercolor"])
    parser.add_argument("--json", type=Path)
    parser.add_argument("--sheet", type=Path)
    parser.add_argument("--params", action="store_true")
    args = parser.parse_args()
    print("| photo | size | look | SSIM to the photo | added texture (L*) |")
    print("| --- | --- | --- | --- | --- |")
    rows, sheet = measure(args.photos, args.sizes, args.effects)
    result: dict = {"looks": rows}
    if args.sheet is not None:
        write_sheet(sheet, args.sizes, args.sheet)
    if args.params:
        print("| effect | parameter | mean change | 99th percentile | visible |")
        print("| --- | --- | --- | --- | --- |")
        result["parameters"] = parameter_reach(args.photos[0])
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=2))
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
