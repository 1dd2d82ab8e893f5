"""Input checks and conversions shared by the filters."""

from __future__ import annotations

from typing import Union

import torch

from wise.errors import WiseError

ParamLike = Union[float, torch.Tensor]
"""A filter parameter: a Python float, a per-batch ``(B,)`` tensor, or a map ``(B, 1, H, W)``."""

REFERENCE_SHORT_SIDE = 512.0


def check_image(image: torch.Tensor, name: str = "image", channels: int | None = None) -> None:
    if not isinstance(image, torch.Tensor):
        raise WiseError(f"{name} must be a torch.Tensor, got {type(image).__name__}")
    if image.dim() != 4:
        raise WiseError(f"{name} must have shape (B, C, H, W), got {tuple(image.shape)}")
    if channels is not None and image.shape[1] != channels:
        raise WiseError(f"{name} must have {channels} channel(s), got shape {tuple(image.shape)}")
    if not image.is_floating_point():
        raise WiseError(f"{name} must be a floating-point tensor, got {image.dtype}")


def as_map(value: ParamLike, ref: torch.Tensor, name: str) -> torch.Tensor:
    """``value`` as a 4-D tensor that broadcasts against ``ref`` (B, C, H, W) over channels.

    Accepts a float, a 0-d or ``(B,)`` tensor, or ``(B, 1, 1, 1)`` / ``(B, 1, H, W)`` maps
    (a batch of 1 broadcasts).
    """
    if not isinstance(value, torch.Tensor):
        return torch.tensor(float(value), dtype=ref.dtype, device=ref.device).view(1, 1, 1, 1)
    b, _, h, w = ref.shape
    v = value.to(dtype=ref.dtype, device=ref.device)
    if v.dim() == 0:
        return v.view(1, 1, 1, 1)
    if v.dim() == 1 and v.shape[0] in (1, b):
        return v.view(-1, 1, 1, 1)
    if v.dim() == 4 and v.shape[0] in (1, b) and v.shape[1] == 1 and tuple(v.shape[2:]) in ((1, 1), (h, w)):
        return v
    raise WiseError(
        f"{name} must be a float, a (B,) tensor or a (B, 1, H, W) map matching the image "
        f"{tuple(ref.shape)}; got shape {tuple(v.shape)}"
    )


def resolution_scale(image: torch.Tensor) -> float:
    """How much larger than the 512-pixel reference the image's short side is."""
    return min(image.shape[-2:]) / REFERENCE_SHORT_SIDE


def max_value(value: torch.Tensor) -> float:
    return float(value.detach().max())
