"""The look sheet (docs/looks.jpg): every preset of every effect on three photos, each beside a
crop at 100 % (one pixel of the render per pixel of the sheet), where an effect's texture shows.

Usage::

    python docs/looks.py --portrait PORTRAIT --landscape LANDSCAPE [-o docs/looks.jpg]

The photos are rendered at a 512-pixel short side, the resolution the effects' sizes are
defined for. The sheet in the repository uses a portrait photo, ``skimage.data.astronaut()``
(NASA, public domain) and "Aitzgorri" by Aitzol Berasategi (CC BY 4.0, Debian package
``lomiri-wallpapers-16.04``: /usr/share/backgrounds/aitzgorri_by_Aitzol_Berasategi.jpg).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image, ImageDraw, ImageFont
from skimage import data

import wise
from wise.io import image_to_tensor, read_image, tensor_to_image

RENDER_SHORT_SIDE = 512
THUMBNAIL_SHORT_SIDE = 224
CROP = 224
"""Side of the 100 % crop, in pixels of the 512-pixel render."""
LABEL_WIDTH = 150
GAP = 6
BACKGROUND = (255, 255, 255)
TEXT = (20, 20, 20)
JPEG_QUALITY = 85


@dataclass(frozen=True)
class Photo:
    name: str
    image: torch.Tensor
    focus: tuple[float, float]
    """Centre of the 100 % crop as fractions of (height, width)."""


def _resized(image: torch.Tensor, short_side: int) -> torch.Tensor:
    height, width = image.shape[-2:]
    factor = short_side / min(height, width)
    size = (round(height * factor), round(width * factor))
    return F.interpolate(image, size=size, mode="area" if factor < 1 else "bilinear")


def _crop(image: torch.Tensor, focus: tuple[float, float]) -> torch.Tensor:
    height, width = image.shape[-2:]
    top = min(max(0, round(focus[0] * height) - CROP // 2), height - CROP)
    left = min(max(0, round(focus[1] * width) - CROP // 2), width - CROP)
    return image[..., top : top + CROP, left : left + CROP]


def _cells(image: torch.Tensor, focus: tuple[float, float]) -> list[np.ndarray]:
    """The render reduced to a thumbnail, and its 100 % crop."""
    return [tensor_to_image(_resized(image, THUMBNAIL_SHORT_SIDE)), tensor_to_image(_crop(image, focus))]


def _font() -> ImageFont.ImageFont:
    try:
        return ImageFont.load_default(size=16)
    except TypeError:  # Pillow < 10.1 has only the small bitmap font
        return ImageFont.load_default()


def _row(label: str, cells: list[np.ndarray], height: int, font: ImageFont.ImageFont) -> Image.Image:
    width = LABEL_WIDTH + sum(cell.shape[1] + GAP for cell in cells)
    row = Image.new("RGB", (width, height + GAP), BACKGROUND)
    ImageDraw.Draw(row).multiline_text((8, 8), label, fill=TEXT, font=font)
    x = LABEL_WIDTH
    for cell in cells:
        row.paste(Image.fromarray(cell), (x, 0))
        x += cell.shape[1] + GAP
    return row


def make_sheet(photos: list[Photo]) -> Image.Image:
    """Rows: the photos, then every effect and preset; each photo as a thumbnail and a 100 % crop."""
    font = _font()
    renders = [_resized(photo.image, RENDER_SHORT_SIDE) for photo in photos]
    height = max(THUMBNAIL_SHORT_SIDE, CROP)
    rows = [_row("photo", [c for p, r in zip(photos, renders) for c in _cells(r, p.focus)], height, font)]
    for name in wise.effects.available():
        effect = wise.effects.create(name).eval()
        for preset in effect.presets:
            cells = []
            for photo, render in zip(photos, renders):
                with torch.no_grad():
                    result = effect(render, effect.preset(preset)[None])
                cells += _cells(result, photo.focus)
            rows.append(_row(f"{name}\n{preset}", cells, height, font))
            print(f"{name} {preset}", flush=True)
    sheet = Image.new("RGB", (max(r.width for r in rows), sum(r.height for r in rows) + GAP), BACKGROUND)
    y = GAP
    for row in rows:
        sheet.paste(row, (0, y))
        y += row.height
    return sheet


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--portrait", required=True, type=Path, help="a portrait photo")
    parser.add_argument("--landscape", required=True, type=Path, help="a landscape photo")
    parser.add_argument("-o", "--output", type=Path, default=Path(__file__).with_name("looks.jpg"))
    args = parser.parse_args()
    torch.manual_seed(0)
    photos = [
        Photo("portrait", read_image(args.portrait), (0.42, 0.5)),
        Photo("astronaut", image_to_tensor(data.astronaut()), (0.3, 0.45)),
        Photo("landscape", read_image(args.landscape), (0.45, 0.3)),
    ]
    make_sheet(photos).save(args.output, quality=JPEG_QUALITY, optimize=True)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
