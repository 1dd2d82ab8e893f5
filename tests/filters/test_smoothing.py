"""The step temperature: the look unchanged at 0, gradients far from the target when raised;
softened gradients: the look unchanged, gradients on the flat side of the threshold."""

from __future__ import annotations

from contextlib import nullcontext

import pytest
import torch

from wise.errors import WiseError
from wise.filters.dog import xdog_threshold
from wise.filters.quantize import quantize
from wise.filters.smoothing import (
    annealed_temperature,
    gradient_softness,
    smoothed_steps,
    softened_gradients,
    step_temperature,
)


def _ramp_image() -> torch.Tensor:
    return torch.linspace(-0.2, 1.0, 64 * 64, dtype=torch.float64).view(1, 1, 64, 64)


def test_at_temperature_zero_the_steps_are_the_filters_themselves() -> None:
    image = _ramp_image()
    expected_threshold = torch.where(image >= 0.3, torch.ones_like(image), 1.0 + torch.tanh(1000.0 * (image - 0.3)))
    levels = torch.linspace(0.0, 1.0, 1000, dtype=torch.float64).view(1, 1, 10, 100)
    expected_levels = ((levels * 6.0).floor().clamp(max=5.0) + 0.5) / 6.0
    assert step_temperature() == 0.0
    for context in (None, 0.0):
        with smoothed_steps(context) if context is not None else nullcontext():
            assert torch.equal(xdog_threshold(image, 0.3, 1000.0), expected_threshold)
            assert torch.equal(quantize(levels, 6.0), expected_levels)


def test_a_raised_temperature_smooths_and_the_context_ends_with_the_block() -> None:
    image = _ramp_image()
    sharp = xdog_threshold(image, 0.3, 1000.0)
    with smoothed_steps(0.5):
        assert step_temperature() == 0.5
        smooth = xdog_threshold(image, 0.3, 1000.0)
    assert step_temperature() == 0.0
    assert float((smooth - sharp).abs().max()) > 0.1 and 0.0 <= float(smooth.min()) and float(smooth.max()) <= 1.0
    # still a threshold: dark well below epsilon, white well above it, monotonic in between
    assert float(smooth.flatten()[0]) < 0.1 and float(smooth.flatten()[-1]) > 0.75
    assert bool((smooth.flatten().diff() >= -1e-12).all())
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(WiseError, match="temperature"):
            with smoothed_steps(bad):
                pass


def test_smoothing_gives_a_gradient_far_from_the_target_threshold() -> None:
    # a DoG response whose pixels all lie above the current threshold and the target's:
    # at temperature 0 moving epsilon changes no pixel, smoothed it pulls towards the target
    image = torch.rand(1, 1, 32, 32, dtype=torch.float64) * 0.4 + 0.5
    target = xdog_threshold(image, 0.7, 1000.0)
    gradients = {}
    for temperature in (0.0, 1.0):
        epsilon = torch.tensor([0.1], dtype=torch.float64, requires_grad=True)
        with smoothed_steps(temperature):
            (xdog_threshold(image, epsilon, 1000.0) - target).abs().mean().backward()
        assert epsilon.grad is not None
        gradients[temperature] = float(epsilon.grad)
    assert gradients[0.0] == 0.0
    assert gradients[1.0] < -1e-3  # descent raises epsilon towards 0.7


def test_smoothed_quantization_passes_gradients_to_the_image_everywhere() -> None:
    image = torch.rand(1, 1, 16, 16, dtype=torch.float64, requires_grad=True)
    quantize(image, 4.0, 0.0).sum().backward()
    assert image.grad is not None and torch.equal(image.grad, torch.ones_like(image))  # straight through
    image.grad = None
    with smoothed_steps(1.0):
        output = quantize(image, 4.0, 0.0)
    output.sum().backward()
    assert image.grad is not None and float(image.grad.std()) > 0.05  # the true slope of the smoothed ramps


def test_annealing_falls_from_the_start_to_zero_and_stays_sharp_at_the_end() -> None:
    values = [annealed_temperature(0.8, step / 100) for step in range(101)]
    assert values[0] == 0.8 and all(a >= b for a, b in zip(values, values[1:]))
    assert all(v == 0.0 for v in values[75:]) and values[74] > 0.0
    assert annealed_temperature(0.0, 0.1) == 0.0
    assert annealed_temperature(1.0, 0.2, sharp_share=0.5) == pytest.approx((1 - 0.4) ** 2)


def test_softened_gradients_keep_the_look_and_reach_the_white_side_of_the_threshold() -> None:
    # pixels just above epsilon are white and the exact step is flat there: a target that wants
    # them black gives epsilon no gradient unless the gradient is softened
    image = torch.linspace(0.32, 0.4, 256, dtype=torch.float64).view(1, 1, 16, 16)
    target = torch.zeros_like(image)
    rendered, gradients = {}, {}
    for softness in (0.0, 0.8):
        epsilon = torch.tensor([0.3], dtype=torch.float64, requires_grad=True)
        with softened_gradients(softness):
            assert gradient_softness() == softness
            rendered[softness] = xdog_threshold(image, epsilon, 1000.0)
        (rendered[softness] - target).abs().mean().backward()
        assert epsilon.grad is not None
        gradients[softness] = float(epsilon.grad)
    assert gradient_softness() == 0.0
    assert torch.equal(rendered[0.8], rendered[0.0]) and bool((rendered[0.0] == 1.0).all())
    assert gradients[0.0] == 0.0
    assert gradients[0.8] < -1e-2  # descent raises epsilon over the pixels, which turns them black
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(WiseError, match="softness"):
            with softened_gradients(bad):
                pass
