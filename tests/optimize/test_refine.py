"""Refinement from a prediction within a time budget."""

from __future__ import annotations

import pytest
import torch
from skimage import data

import wise
from wise import metrics
from wise.errors import WiseError
from wise.optimize.refine import refine
from wise.optimize.trials import content_at


@pytest.fixture(scope="module")
def photo() -> torch.Tensor:
    return content_at(torch.from_numpy(data.astronaut()).permute(2, 0, 1)[None].float() / 255, 96)


def test_refinement_moves_a_distant_start_towards_the_example_within_its_budget(photo: torch.Tensor) -> None:
    effect = wise.effects.create("xdog")
    truth = effect.preset("lines")
    with torch.no_grad():
        example = effect(photo, truth)
    start = effect.default_params()
    with torch.no_grad():
        before = metrics.ssim(effect(photo, start), example)
    outcome = refine(effect, photo, example, start, budget=5.0)
    with torch.no_grad():
        after = metrics.ssim(effect(photo, outcome.params), example)
    assert outcome.seconds <= 5.0 + 0.3 and len(outcome.losses) > 20
    assert after > before + 0.03, (before, after)
    assert outcome.losses[-1] < outcome.losses[0]


def test_refinement_iterations_can_be_capped_and_the_budget_must_be_positive(photo: torch.Tensor) -> None:
    effect = wise.effects.create("cartoon")
    start = effect.default_params()
    outcome = refine(effect, photo, photo, start, budget=30.0, max_iterations=4)
    assert len(outcome.losses) == 4 and outcome.seconds < 30.0
    with pytest.raises(WiseError, match="budget"):
        refine(effect, photo, photo, start, budget=0.0)
