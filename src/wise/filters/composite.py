"""Porter–Duff alpha compositing and layer blend modes."""

from __future__ import annotations

from typing import Callable, Union

import torch

from wise.errors import WiseError
from wise.filters._checks import ParamLike, as_map, check_image

Factor = Union[float, torch.Tensor]
FactorFn = Callable[[torch.Tensor, torch.Tensor], tuple[Factor, Factor]]

ALPHA_FLOOR = 1e-6
"""Resulting alpha below which the colour fades to 0 instead of dividing by ~0."""
OVERLAY_SPLIT = 0.5
"""Base value where overlay switches from multiply to screen."""

# Porter & Duff 1984, Table 1: the fractions (F_A, F_B) of source and destination that
# survive, as functions of the source and destination alpha.
_PORTER_DUFF: dict[str, FactorFn] = {
    "clear": lambda a_s, a_d: (0.0, 0.0),
    "source": lambda a_s, a_d: (1.0, 0.0),
    "destination": lambda a_s, a_d: (0.0, 1.0),
    "over": lambda a_s, a_d: (1.0, 1.0 - a_s),
    "destination_over": lambda a_s, a_d: (1.0 - a_d, 1.0),
    "in": lambda a_s, a_d: (a_d, 0.0),
    "destination_in": lambda a_s, a_d: (0.0, a_s),
    "out": lambda a_s, a_d: (1.0 - a_d, 0.0),
    "destination_out": lambda a_s, a_d: (0.0, 1.0 - a_s),
    "atop": lambda a_s, a_d: (a_d, 1.0 - a_s),
    "destination_atop": lambda a_s, a_d: (1.0 - a_d, a_s),
    "xor": lambda a_s, a_d: (1.0 - a_d, 1.0 - a_s),
}
OPERATORS = tuple(_PORTER_DUFF)


def _overlay(base: torch.Tensor, layer: torch.Tensor) -> torch.Tensor:
    dark = 2.0 * base * layer
    light = 1.0 - 2.0 * (1.0 - base) * (1.0 - layer)
    return torch.where(base < OVERLAY_SPLIT, dark, light)


_BLEND_MODES: dict[str, Callable[[torch.Tensor, torch.Tensor], torch.Tensor]] = {
    "multiply": lambda base, layer: base * layer,
    "screen": lambda base, layer: 1.0 - (1.0 - base) * (1.0 - layer),
    "overlay": _overlay,
    "darken": torch.minimum,
    "lighten": torch.maximum,
}
BLEND_MODES = tuple(_BLEND_MODES)


def _check_pair(first: torch.Tensor, second: torch.Tensor, names: tuple[str, str]) -> torch.Tensor:
    """Checks two images that are combined and returns the one with the larger batch."""
    check_image(first, names[0])
    check_image(second, names[1])
    same_pixels = first.shape[1:] == second.shape[1:]
    batches_broadcast = first.shape[0] == second.shape[0] or 1 in (first.shape[0], second.shape[0])
    if not (same_pixels and batches_broadcast):
        raise WiseError(
            f"{names[0]} {tuple(first.shape)} and {names[1]} {tuple(second.shape)} must have the same "
            "channels and size (a batch of 1 broadcasts)"
        )
    return first if first.shape[0] >= second.shape[0] else second


def composite(
    source: torch.Tensor,
    destination: torch.Tensor,
    operator: str = "over",
    source_alpha: ParamLike = 1.0,
    destination_alpha: ParamLike = 1.0,
    return_alpha: bool = False,
) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
    """Porter–Duff compositing (Porter & Duff 1984) of straight (non-premultiplied) colour.

    With F_A, F_B the operator's fractions (e.g. ``over``: 1 and 1 - alpha_s), the result
    is alpha = F_A alpha_s + F_B alpha_d and premultiplied colour
    F_A alpha_s C_s + F_B alpha_d C_d. The returned colour is straight again (divided by
    alpha), so it can be filtered or composited further with the returned alpha; where
    the result is transparent (alpha ~ 0, e.g. ``clear``, or ``xor`` of opaque layers)
    the colour is 0. For colour composited over black, multiply it by the alpha.

    Args:
        source, destination: ``(B, C, H, W)`` straight colour (a batch of 1 broadcasts).
        operator: one of ``OPERATORS``: clear, source, destination, over,
            destination_over, in, destination_in, out, destination_out, atop,
            destination_atop, xor.
        source_alpha, destination_alpha: coverage in [0, 1]: a float, ``(B,)`` tensor or
            ``(B, 1, H, W)`` map.
        return_alpha: also return the resulting alpha ``(B, 1, H, W)``.

    Returns:
        ``(B, C, H, W)`` straight colour, or ``(colour, alpha)`` with ``return_alpha``.
    """
    if operator not in _PORTER_DUFF:
        raise WiseError(f"unknown compositing operator {operator!r}; known: {', '.join(OPERATORS)}")
    ref = _check_pair(source, destination, ("source", "destination"))
    alpha_s = as_map(source_alpha, ref, "source_alpha")
    alpha_d = as_map(destination_alpha, ref, "destination_alpha")
    factor_s, factor_d = _PORTER_DUFF[operator](alpha_s, alpha_d)
    weight_s = factor_s * alpha_s
    weight_d = factor_d * alpha_d
    alpha = weight_s + weight_d
    colour = (weight_s * source + weight_d * destination) / alpha.clamp_min(ALPHA_FLOOR)
    colour = colour.expand_as(ref)
    if not return_alpha:
        return colour
    b, _, h, w = ref.shape
    return colour, alpha.expand(b, 1, h, w)


def blend(base: torch.Tensor, layer: torch.Tensor, mode: str = "multiply", opacity: ParamLike = 1.0) -> torch.Tensor:
    """Blend ``layer`` onto ``base`` with a separable blend mode (as in the W3C Compositing spec).

    Formulas per channel with base a and layer b in [0, 1]: multiply a b; screen
    1 - (1 - a)(1 - b); overlay 2 a b where a < 0.5, else 1 - 2 (1 - a)(1 - b);
    darken min(a, b); lighten max(a, b). The result is mixed with the base by
    ``opacity``: a + opacity (blend - a).

    Args:
        base, layer: ``(B, C, H, W)`` (a batch of 1 broadcasts).
        mode: one of ``BLEND_MODES``.
        opacity: a float, ``(B,)`` tensor or ``(B, 1, H, W)`` map; 0 keeps the base.

    Returns:
        ``(B, C, H, W)``.
    """
    if mode not in _BLEND_MODES:
        raise WiseError(f"unknown blend mode {mode!r}; known: {', '.join(BLEND_MODES)}")
    ref = _check_pair(base, layer, ("base", "layer"))
    blended = _BLEND_MODES[mode](base, layer)
    return torch.lerp(base, blended, as_map(opacity, ref, "opacity")).expand_as(ref)
