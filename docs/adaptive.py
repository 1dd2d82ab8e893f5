"""The content-adaptive sheet (docs/adaptive.jpg): per task, a photo held out of training, the
effect at its preset, the mask the local model paints for the task's parameter, and the
photo rendered with the painted masks.

Usage::

    python docs/adaptive.py [-o docs/adaptive.jpg] [--model TASK=FILE ...]
    python docs/adaptive.py -o ablation.jpg --task contours --model "L1=a.safetensors" --model "L1+TV=b.safetensors"

Without ``--model`` the built-in local models (``builtin:TASK``, those shipped) are shown. With ``--task``,
every row is a model of that task (labelled as given) on the same photo. The photos are
``skimage.data`` pictures held out of training, at a 256-pixel short side (the models' own).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch
from PIL import Image
from sheet import labelled_sheet
from skimage import data

import wise
from wise.errors import WiseError
from wise.io import image_to_tensor, tensor_to_image
from wise.optimize.report import heatmap
from wise.ppn.modelfile import builtin_model_path
from wise.ppn.predictor import LocalPredictor, at_short_side
from wise.train.adaptive import TASKS, task_preset

SHORT_SIDE = 256
CELL = 220
PHOTOS = {"contours": "coffee", "details": "chelsea", "background": "astronaut"}
JPEG_QUALITY = 85


def _row(task: str, model: str, label: str) -> list[tuple[str, Image.Image]]:
    effect = wise.effects.create("xdog")
    change = TASKS[task].change(effect.name)
    preset = task_preset(TASKS[task], effect)
    photo = at_short_side(image_to_tensor(getattr(data, PHOTOS[task])()), SHORT_SIDE)
    masks = LocalPredictor(model, effect.name)(photo)
    index = effect.param_names.index(change.parameter)
    spec = effect.param_specs[index]
    real = spec.min + (masks[0, index] + 0.5) * (spec.max - spec.min)
    with torch.no_grad():
        at_preset = effect(photo, effect.preset(preset)[None])
        adaptive = effect(photo, masks)
    return [
        (f"{label}: photo", Image.fromarray(tensor_to_image(photo))),
        (f"preset {preset}", Image.fromarray(tensor_to_image(at_preset))),
        (
            f"painted {change.parameter} [{spec.min:g}, {spec.max:g}]",
            Image.fromarray(heatmap(real, spec.min, spec.max)),
        ),
        ("content-adaptive result", Image.fromarray(tensor_to_image(adaptive))),
    ]


def _shipped(task: str) -> bool:
    try:
        builtin_model_path("xdog", task)
    except WiseError:
        return False
    return True


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", default=str(Path(__file__).with_name("adaptive.jpg")))
    parser.add_argument("--model", action="append", default=[], metavar="TASK=FILE")
    parser.add_argument("--task", choices=tuple(PHOTOS), help="every model is of this task; --model LABEL=FILE")
    args = parser.parse_args()
    shipped = {task: f"builtin:{task}" for task in PHOTOS if _shipped(task)}
    models = dict(item.split("=", 1) for item in args.model) or shipped
    rows = [_row(args.task or name, model, name) for name, model in models.items()]
    sheet = labelled_sheet(rows, CELL)
    sheet.save(args.output, quality=JPEG_QUALITY)
    print(args.output)


if __name__ == "__main__":
    main()
