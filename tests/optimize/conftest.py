from dataclasses import dataclass

import pytest
import torch
import torch.nn.functional as F

from wise import effects
from wise.effects.base import Effect


@dataclass
class OffTheStaircase:
    """A cartoon of the astronaut at its defaults (``truth``, rendered as ``target``) and the same
    parameters with ``bins`` far off on the staircase (``wrong``)."""

    cartoon: Effect
    content: torch.Tensor
    truth: torch.Tensor
    wrong: torch.Tensor
    target: torch.Tensor


@pytest.fixture
def off_the_staircase(astronaut: torch.Tensor) -> OffTheStaircase:
    cartoon = effects.create("cartoon").eval()
    content = F.interpolate(astronaut, size=(64, 64), mode="area")
    truth = cartoon.default_params().reshape(1, -1)
    wrong = truth.clone()
    wrong[0, cartoon.param_names.index("bins")] = 0.4
    with torch.no_grad():
        target = cartoon(content, truth)
    return OffTheStaircase(cartoon, content, truth, wrong, target)
