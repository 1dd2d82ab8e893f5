"""The shipped local models: small, of their task, and painting where their task's rule points."""

from __future__ import annotations

import pytest
import torch
from skimage import data

import wise
from wise.io import image_to_tensor
from wise.ppn.modelfile import builtin_model_path
from wise.ppn.predictor import LocalPredictor, at_short_side
from wise.train.adaptive import preset_value, task_preset
from wise.train.tasks import TASKS

SHIPPED = ("contours", "details", "background")
PHOTOS = {"contours": "coffee", "details": "chelsea", "background": "astronaut"}
"""A photo held out of every model's training per task."""
SIDE = 256
"""The models' working size."""
BORDER = 0.2
"""Share of the picture's side counted as its border."""


def _painted(task: str, photo: torch.Tensor) -> torch.Tensor:
    """The real values the built-in model of ``task`` paints for its parameter, ``(h, w)``."""
    effect = wise.effects.create("xdog")
    predictor = LocalPredictor(f"builtin:{task}", "xdog")
    masks = predictor(photo)
    spec = effect.spec(TASKS[task].change("xdog").parameter)
    return spec.min + (masks[0, effect.param_names.index(spec.name)] + 0.5) * (spec.max - spec.min)


@pytest.mark.parametrize("task", SHIPPED)
def test_a_shipped_local_model_is_small_and_of_its_task(task: str) -> None:
    path = builtin_model_path("xdog", task)
    assert path.stat().st_size < 4 * 1000**2
    predictor = LocalPredictor(f"builtin:{task}", "xdog")
    assert predictor.info.kind == "local" and predictor.info.settings["task"] == task


def test_the_background_model_brightens_the_border_more_than_the_subject() -> None:
    # the astronaut in the middle of her portrait is the subject; the flag, the shuttle and the
    # wall at the borders are background, which the task pales with a higher brightness
    brightness = _painted("background", image_to_tensor(data.astronaut()))
    height, width = brightness.shape
    rows, cols = int(height * BORDER), int(width * BORDER)
    centre = brightness[rows:-rows, cols:-cols]
    border = torch.cat([brightness[:rows].flatten(), brightness[-rows:].flatten()])
    task, effect = TASKS["background"], wise.effects.create("xdog")
    change = task.change("xdog")
    at_preset = preset_value(effect, task_preset(task, effect), change.parameter)
    assert float(border.mean()) > float(centre.mean()) + 0.25 * (change.inside - at_preset)


@pytest.mark.parametrize("task", SHIPPED)
def test_a_shipped_model_departs_from_the_preset_inside_its_rules_region_more_than_outside(task: str) -> None:
    photo = at_short_side(image_to_tensor(getattr(data, PHOTOS[task])()), SIDE)
    painted = _painted(task, photo)
    region = TASKS[task].rule(photo)[0, 0] > 0.5
    effect = wise.effects.create("xdog")
    change = TASKS[task].change("xdog")
    at_preset = preset_value(effect, task_preset(TASKS[task], effect), change.parameter)
    departure = (painted - at_preset) / (change.inside - at_preset)  # 0 at the preset, 1 at the task's value
    assert region.any() and (~region).any()
    assert float(departure[region].mean()) > float(departure[~region].mean()) + 0.2, task
