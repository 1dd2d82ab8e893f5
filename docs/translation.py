"""The image-to-image sheet (docs/translation.jpg): per photo held out of training, the synthetic
artist's drawing (the ground truth of ``wise data drawing``), then every model's drawing, and
for models with an effect and a CNN also their effect stage.

Usage::

    python docs/translation.py -o docs/translation.jpg --model "PPN + XDoG + ResNet=full.safetensors" \\
        --model "CNN only (ResNet)=cnn.safetensors" ...

The photos are ``skimage.data`` pictures held out of training, at a 256-pixel short side.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from PIL import Image
from sheet import labelled_sheet
from skimage import data

from wise.io import image_to_tensor, tensor_to_image
from wise.ppn.modelfile import model_info
from wise.ppn.predictor import LocalPredictor, at_short_side
from wise.train.drawing import draw

SHORT_SIDE = 256
CELL = 200
PHOTOS = ("astronaut", "coffee", "chelsea")
JPEG_QUALITY = 85


def _picture(tensor) -> Image.Image:
    return Image.fromarray(tensor_to_image(tensor.clamp(0.0, 1.0)))


def _square(image):
    side = min(image.shape[:2])
    top, left = (image.shape[0] - side) // 2, (image.shape[1] - side) // 2
    return image[top : top + side, left : left + side]


def _row(name: str, models: dict[str, LocalPredictor]) -> list[tuple[str, Image.Image]]:
    photo = at_short_side(image_to_tensor(_square(getattr(data, name)())), SHORT_SIDE)
    cells = [("photo", _picture(photo)), ("artist (ground truth)", _picture(draw(photo)))]
    for label, predictor in models.items():
        made = predictor.stages(photo)
        if predictor.translates and predictor.effect is not None and predictor.network.post is not None:
            cells.append((f"{label}: effect stage", _picture(made.stage)))
        cells.append((label, _picture(made.result)))
    return cells


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", default=str(Path(__file__).with_name("translation.jpg")))
    parser.add_argument("--model", action="append", required=True, metavar="LABEL=FILE")
    args = parser.parse_args()
    models = {}
    for item in args.model:
        label, path = item.split("=", 1)
        models[label] = LocalPredictor(path, model_info(path).effect)
    sheet = labelled_sheet([_row(name, models) for name in PHOTOS], CELL)
    sheet.save(args.output, quality=JPEG_QUALITY)
    print(args.output)


if __name__ == "__main__":
    main()
