"""A coordinate search over a grid for the parameters that gradient descent cannot find.

Some of an effect's parameters have no useful gradient far from their value: a symmetric blur's
reach (watercolor's ``bleeding``) has a zero gradient at zero reach, so a descent that touches
the bound stays there, and a structure scale (the washes' ``abstraction``) is invisible on the
reduced copies where the coarse levels start. Effects name them in
:attr:`wise.effects.base.Effect.searched_params`; before the fine iterations,
:func:`coordinate_search` tries every value of a grid for each of them in turn, the others
held, and keeps the one with the lowest loss. It renders forward only, without autograd.
"""

from __future__ import annotations

import torch

from wise.effects.base import Effect
from wise.errors import WiseError
from wise.params import NORMALIZED_MAX, NORMALIZED_MIN

GRID_VALUES = 7
"""Values tried per parameter, evenly spaced over its normalized range (ends included)."""
PASSES = 2
"""Passes over the searched parameters: a second pass sees the others' new values."""


def coordinate_search(
    effect: Effect,
    content: torch.Tensor,
    target: torch.Tensor,
    params: torch.Tensor,
    names: tuple[str, ...] | None = None,
    values: int = GRID_VALUES,
    passes: int = PASSES,
) -> tuple[torch.Tensor, float]:
    """The global ``params`` ``(1, P)`` (normalized) with each parameter of ``names`` (default:
    the effect's :attr:`~wise.effects.base.Effect.searched_params`) set to the grid value of
    lowest mean squared difference between ``effect(content)`` and ``target``, and that
    difference. ``content`` and ``target``: ``(1, 3, H, W)``. Costs ``1 + len(names) * values
    * passes`` renders."""
    if content.shape != target.shape:
        raise WiseError(f"content {tuple(content.shape)} and target {tuple(target.shape)} differ in size")
    names = effect.searched_params if names is None else names
    unknown = [name for name in names if name not in effect.param_names]
    if unknown:
        raise WiseError(f"{effect.name} has no parameter {', '.join(unknown)}; use {', '.join(effect.param_names)}")
    if values < 2:
        raise WiseError(f"a grid needs at least 2 values, got {values}")
    best = params.detach().reshape(1, -1).clone()
    grid = torch.linspace(NORMALIZED_MIN, NORMALIZED_MAX, values).tolist()
    with torch.no_grad():
        lowest = _loss(effect, content, target, best)
        for _ in range(passes):
            for index in (effect.param_names.index(name) for name in names):
                for value in grid:
                    candidate = best.clone()
                    candidate[0, index] = value
                    loss = _loss(effect, content, target, candidate)
                    if loss < lowest:
                        lowest, best = loss, candidate
    return best, lowest


def _loss(effect: Effect, content: torch.Tensor, target: torch.Tensor, params: torch.Tensor) -> float:
    return float((effect(content, params.to(content)).clamp(0.0, 1.0) - target).square().mean())
