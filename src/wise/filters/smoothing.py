"""A temperature that smooths the step-like operations of the effects during optimization.

XDoG's soft threshold and the luminance quantization are steps: away from their edges the
image does not change when their parameters do, so a loss that compares the output with a
distant target has no gradient with respect to ``blackness`` or ``bins``. Graduated
non-convexity (Blake & Zisserman 1987) starts the optimization on a smoothed version of such
steps and sharpens them as it goes. The temperature is not a parameter of the look: at 0,
the default, every step is exactly the filter it was; optimization and training raise it
for the forward and backward passes they run, inside :func:`smoothed_steps`.

Smoothing changes the picture that is compared with the target. A surrogate gradient
(straight-through estimator, Bengio et al. 2013) leaves it alone: inside
:func:`softened_gradients` the steps render exactly, but backward differentiates a wider ramp
in their place, so pixels on the wrong side of a threshold, which the exact step leaves flat,
still tell the parameters which way to move.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar

from wise.errors import WiseError

_TEMPERATURE: ContextVar[float] = ContextVar("step_temperature", default=0.0)
_GRADIENT_SOFTNESS: ContextVar[float] = ContextVar("gradient_softness", default=0.0)


@contextmanager
def _within(variable: ContextVar[float], value: float, name: str) -> Iterator[None]:
    """``variable`` set to ``value`` (checked to be from 0 to 1) for the block."""
    if not (isinstance(value, (int, float)) and math.isfinite(value) and 0.0 <= value <= 1.0):
        raise WiseError(f"{name} must be from 0 to 1, got {value!r}")
    token = variable.set(float(value))
    try:
        yield
    finally:
        variable.reset(token)


def step_temperature() -> float:
    """The temperature of the steps in force here: 0 (sharp, the look itself) to 1 (smoothest)."""
    return _TEMPERATURE.get()


@contextmanager
def smoothed_steps(temperature: float) -> Iterator[None]:
    """Render with the step-like operations smoothed at ``temperature`` (0 to 1).

    Stages recomputed during backward run under the context of their forward pass, so a
    backward after the block still sees the temperature the forward pass had.
    """
    with _within(_TEMPERATURE, temperature, "the step temperature"):
        yield


def gradient_softness() -> float:
    """The softness of the steps' surrogate gradients in force here: 0 (their own) to 1 (smoothest)."""
    return _GRADIENT_SOFTNESS.get()


@contextmanager
def softened_gradients(softness: float) -> Iterator[None]:
    """Render the steps exactly but differentiate them as ramps widened by ``softness`` (0 to 1,
    on the scale of the step temperature); 0 keeps their own gradients."""
    with _within(_GRADIENT_SOFTNESS, softness, "the gradient softness"):
        yield


def annealed_temperature(start: float, progress: float, sharp_share: float = 0.25) -> float:
    """The temperature at ``progress`` (0 to 1) of a schedule from ``start`` down to 0.

    It falls quadratically (most of the way early, slowly near the sharp end) and stays 0
    for the last ``sharp_share`` of the schedule, so the result is optimized on the look itself.
    """
    if start <= 0.0:
        return 0.0
    smoothing_end = 1.0 - sharp_share
    if progress >= smoothing_end:
        return 0.0
    remaining = 1.0 - max(0.0, progress) / smoothing_end
    return start * remaining * remaining
