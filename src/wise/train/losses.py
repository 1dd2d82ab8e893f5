"""The losses of the supplement's ablation: in image space (the example re-rendered with the
predicted parameters, gradients through the differentiable effect) or in parameter space."""

from __future__ import annotations

import torch

from wise.effects.base import Effect
from wise.errors import WiseError
from wise.train.choices import LOSSES


def _distance(a: torch.Tensor, b: torch.Tensor, norm: str) -> torch.Tensor:
    difference = a - b
    return difference.abs().mean() if norm == "l1" else difference.square().mean()


def prediction_loss(
    kind: str,
    predicted: torch.Tensor,
    truth: torch.Tensor,
    effect: Effect | None = None,
    photo: torch.Tensor | None = None,
    example: torch.Tensor | None = None,
    scale: float | None = None,
) -> torch.Tensor:
    """``param-l1`` / ``param-l2``: predicted against true normalized parameters ``(B, P)``;
    ``image-l1`` / ``image-l2``: ``effect(photo, predicted)`` (at the effect's ``scale`` of the
    whole picture, see :class:`wise.effects.base.RenderContext`) against ``example``."""
    if kind not in LOSSES:
        raise WiseError(f"unknown loss {kind!r}; use one of {', '.join(LOSSES)}")
    space, norm = kind.split("-")
    if space == "param":
        return _distance(predicted, truth, norm)
    if effect is None or photo is None or example is None:
        raise WiseError(f"the {kind} loss needs the effect, the photos and the examples")
    return _distance(effect(photo, predicted, scale=scale), example, norm)


def total_variation(masks: torch.Tensor) -> torch.Tensor:
    """Mean absolute difference of neighbouring pixels of ``(B, C, H, W)`` masks, across and
    down (anisotropic total variation): how far the masks are from piecewise constant."""
    across = (masks[..., :, 1:] - masks[..., :, :-1]).abs().mean()
    down = (masks[..., 1:, :] - masks[..., :-1, :]).abs().mean()
    return across + down
