"""The prediction sheet (docs/prediction.jpg): per effect, a photo, a stylized example of it,
the built-in model's prediction re-rendered, and the prediction refined as ``wise predict``
refines it by default.

Usage::

    python docs/prediction.py [-o docs/prediction.jpg]

The photos are ``skimage.data.coffee()`` and ``chelsea()`` (both held out of training) at a
512-pixel short side; each example is a preset with a few parameters moved, so that it is no
preset the model could have memorized.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch
from PIL import Image, ImageDraw, ImageFont
from skimage import data

import wise
from wise import metrics
from wise.io import image_to_tensor, tensor_to_image
from wise.optimize.refine import answers, refine
from wise.optimize.settings import DEFAULT_BUDGET
from wise.ppn.predictor import Predictor, at_short_side
from wise.render import render

RENDER_SHORT_SIDE = 512
CELL_HEIGHT = 200
GAP = 6
LABEL_HEIGHT = 22
EXAMPLES = (
    ("xdog", "coffee", "lines", {"blackness": 0.2, "contour": 1.5}),
    ("cartoon", "chelsea", "bold", {"bins": 5, "saturation": 1.8}),
    ("watercolor", "coffee", "pale", {"flatness": 0.8}),
    ("oilpaint", "chelsea", "impasto", {"brightness": 0.05}),
)
JPEG_QUALITY = 85


def _photo(name: str) -> torch.Tensor:
    return at_short_side(image_to_tensor(getattr(data, name)()), RENDER_SHORT_SIDE)


def _cell(image: torch.Tensor) -> Image.Image:
    picture = Image.fromarray(tensor_to_image(image))
    width = round(picture.width * CELL_HEIGHT / picture.height)
    return picture.resize((width, CELL_HEIGHT), Image.Resampling.LANCZOS)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", default=str(Path(__file__).with_name("prediction.jpg")))
    args = parser.parse_args()
    rows = []
    for effect_name, photo_name, preset, changes in EXAMPLES:
        effect = wise.effects.create(effect_name)
        known = {k: v for k, v in changes.items() if k in effect.param_names}
        truth = effect.params_from_dict(known, preset=preset)[None]
        photo = _photo(photo_name)
        with torch.no_grad():
            example = render(effect, photo, truth)
            predicted = Predictor(None, effect_name)(photo, example)
            rendered = render(effect, photo, predicted)
        outcome = refine(effect, photo, example, predicted, DEFAULT_BUDGET)
        # as wise predict: the best of the network alone and the refinement's answers
        with torch.no_grad():
            renders = [render(effect, photo, p) for p in (predicted, *(answer for _, answer in answers(outcome)))]
            refined = max(renders, key=lambda r: metrics.ssim(r, example))
        scores = (metrics.ssim(rendered, example), metrics.ssim(refined, example))
        rows.append((effect_name, [_cell(photo), _cell(example), _cell(rendered), _cell(refined)], scores))
    font = ImageFont.load_default()
    width = max(sum(c.width for c in cells) + GAP * (len(cells) + 1) for _, cells, _ in rows)
    height = len(rows) * (CELL_HEIGHT + LABEL_HEIGHT + GAP) + GAP
    sheet = Image.new("RGB", (width, height), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    top = GAP
    for effect_name, cells, (predicted_score, refined_score) in rows:
        left = GAP
        labels = (
            "photo",
            f"{effect_name} example",
            f"network (SSIM {predicted_score:.2f})",
            f"refined {DEFAULT_BUDGET:g} s (SSIM {refined_score:.2f})",
        )
        for label, cell in zip(labels, cells):
            draw.text((left, top), label, fill=(20, 20, 20), font=font)
            sheet.paste(cell, (left, top + LABEL_HEIGHT))
            left += cell.width + GAP
        top += CELL_HEIGHT + LABEL_HEIGHT + GAP
    sheet.save(args.output, quality=JPEG_QUALITY)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
