"""A labelled contact sheet of every effect and preset on one photo."""

from __future__ import annotations

import time
from typing import Callable

import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image, ImageDraw, ImageFont

from wise import effects
from wise.io import tensor_to_image
from wise.render import render

LABEL_HEIGHT = 28
MARGIN = 8
BACKGROUND = (255, 255, 255)
TEXT = (20, 20, 20)


def _fit(image: torch.Tensor, size: int) -> torch.Tensor:
    height, width = image.shape[-2:]
    factor = size / min(height, width)
    if factor >= 1.0:
        return image
    target = (max(8, round(height * factor)), max(8, round(width * factor)))
    return F.interpolate(image, size=target, mode="area")


def _font() -> ImageFont.ImageFont:
    try:
        return ImageFont.load_default(size=18)
    except TypeError:  # Pillow < 10.1 has only the small bitmap font
        return ImageFont.load_default()


def make_sheet(
    image: torch.Tensor,
    size: int = 512,
    names: list[str] | None = None,
    device: torch.device | str = "cpu",
    progress: Callable[[str, str, float], None] | None = None,
) -> Image.Image:
    """Render every preset of every effect (or of ``names``) on ``image`` (1, 3, H, W).

    The image is first reduced so that its short side is at most ``size``. Row by row:
    the photo, then one row per effect with its presets; each cell labelled.
    """
    photo = _fit(image, size)
    cells: list[list[tuple[str, np.ndarray]]] = [[("original", tensor_to_image(photo))]]
    for name in names or effects.available():
        effect = effects.create(name).to(device).eval()
        row = []
        for preset in effect.presets:
            start = time.perf_counter()
            result = render(effect, photo, effect.preset(preset)[None], device=device)
            if progress is not None:
                progress(name, preset, time.perf_counter() - start)
            row.append((f"{name} / {preset}", tensor_to_image(result)))
        cells.append(row)
    cell_h, cell_w = photo.shape[-2], photo.shape[-1]
    columns = max(len(row) for row in cells)
    sheet = Image.new(
        "RGB",
        (MARGIN + columns * (cell_w + MARGIN), MARGIN + len(cells) * (cell_h + LABEL_HEIGHT + MARGIN)),
        BACKGROUND,
    )
    draw, font = ImageDraw.Draw(sheet), _font()
    for r, row in enumerate(cells):
        for c, (label, pixels) in enumerate(row):
            x, y = MARGIN + c * (cell_w + MARGIN), MARGIN + r * (cell_h + LABEL_HEIGHT + MARGIN)
            sheet.paste(Image.fromarray(pixels), (x, y))
            draw.text((x + 2, y + cell_h + 4), label, fill=TEXT, font=font)
    return sheet
