"""Effect parameters: declared specs, the normalized space and parameter masks.

Every effect declares an ordered tuple of :class:`ParamSpec`. Effects take their
parameters in a *normalized* space where ``-0.5`` maps to ``spec.min`` and ``+0.5``
to ``spec.max`` (linearly), so that optimizers, sliders and networks see the same
scale for every parameter.

What a range means: ``[min, max]`` is the range offered to people and to
optimizers (sliders, ``--set``, random sampling and optimization clamp to it); per-pixel
masks fitted to a reference may go as far as a spec's ``reach`` (:func:`mask_bounds`: the
colour offsets, so that they can give a pixel any colour).
The mapping itself is linear and defined everywhere, so an effect renders any
finite value; a preset may deliberately sit outside the declared range (the
public reference XDoG's sketch values use ``stroke_width`` 0.2 < 0.3) and renders
exactly as authored.

Parameters come either global, shape ``(B, P)``, or as local masks
``(B, P, h, w)`` of any resolution, which are resized bilinearly to the image:
a mask stays valid at every output resolution.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import torch
import torch.nn.functional as F

from wise.errors import WiseError
from wise.paramspec import NORMALIZED_MAX, NORMALIZED_MIN, ParamSpec

Specs = Sequence[ParamSpec]


def _range_tensors(specs: Specs, like: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    lows = torch.tensor([s.min for s in specs], dtype=like.dtype, device=like.device)
    spans = torch.tensor([s.span for s in specs], dtype=like.dtype, device=like.device)
    shape = (1, len(specs)) + (1,) * (like.dim() - 2)
    return lows.view(shape), spans.view(shape)


def to_real(params: torch.Tensor, specs: Specs) -> torch.Tensor:
    """Normalized ``(B, P)`` or ``(B, P, h, w)`` values to real units."""
    if params.dim() == 1:
        return to_real(params.unsqueeze(0), specs).squeeze(0)
    lows, spans = _range_tensors(specs, params)
    return (params - NORMALIZED_MIN) * spans + lows


def to_normalized(values: torch.Tensor, specs: Specs) -> torch.Tensor:
    """Real-unit ``(B, P)`` or ``(B, P, h, w)`` values to the normalized space."""
    if values.dim() == 1:
        return to_normalized(values.unsqueeze(0), specs).squeeze(0)
    lows, spans = _range_tensors(specs, values)
    return (values - lows) / spans + NORMALIZED_MIN


def from_dict(specs: Specs, values: Mapping[str, float], base: Mapping[str, float] | None = None) -> torch.Tensor:
    """A ``(P,)`` normalized tensor from real values by name.

    Names missing from ``values`` take ``base`` (if given) or the spec default.
    Unknown names raise :class:`WiseError`.
    """
    names = [s.name for s in specs]
    unknown = sorted(set(values) - set(names))
    if unknown:
        raise WiseError(f"unknown parameter(s) {', '.join(unknown)}; known: {', '.join(names)}")
    real = []
    for spec in specs:
        if spec.name in values:
            real.append(float(values[spec.name]))
        elif base is not None and spec.name in base:
            real.append(float(base[spec.name]))
        else:
            real.append(spec.default)
    return torch.tensor([s.to_normalized(v) for s, v in zip(specs, real)], dtype=torch.float32)


def to_dict(specs: Specs, params: torch.Tensor) -> dict[str, float]:
    """Real values by name from a ``(P,)`` normalized tensor (or the mean of a mask)."""
    if params.dim() == 3:
        params = params.mean(dim=(1, 2))
    if params.dim() != 1 or params.shape[0] != len(specs):
        raise WiseError(f"expected {len(specs)} parameters, got a tensor of shape {tuple(params.shape)}")
    return {s.name: s.to_real(float(v)) for s, v in zip(specs, params.detach().cpu())}


def clamp(params: torch.Tensor) -> torch.Tensor:
    """Clamp normalized parameters to the declared ranges."""
    return params.clamp(NORMALIZED_MIN, NORMALIZED_MAX)


def mask_bounds(specs: Specs, like: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Normalized lower and upper bounds of per-pixel masks, each ``(1, P, 1, 1)``: the
    declared ranges, widened to each spec's ``reach``."""
    reaches = [spec.reach or (spec.min, spec.max) for spec in specs]
    low = [spec.to_normalized(reach[0]) for spec, reach in zip(specs, reaches)]
    high = [spec.to_normalized(reach[1]) for spec, reach in zip(specs, reaches)]
    shape = (1, len(specs), 1, 1)
    return like.new_tensor(low).view(shape), like.new_tensor(high).view(shape)


def clamp_masks(masks: torch.Tensor, specs: Specs) -> torch.Tensor:
    """``(B, P, h, w)`` normalized masks clamped in place to :func:`mask_bounds`."""
    low, high = mask_bounds(specs, masks)
    return torch.maximum(torch.minimum(masks, high, out=masks), low, out=masks)


def clamp_edit(edited: torch.Tensor, before: torch.Tensor) -> torch.Tensor:
    """Normalized values after an edit (a brush stroke, a slider), clamped to the declared range;
    a value that was outside it (a preset, a fitted colour offset) may move back towards the range
    but not further out, so an edit never makes it jump."""
    return torch.maximum(torch.minimum(edited, before.clamp_min(NORMALIZED_MAX)), before.clamp_max(NORMALIZED_MIN))


def check_params(params: torch.Tensor, specs: Specs, batch: int) -> torch.Tensor:
    """Validate the shape of normalized parameters; return them as ``(B, P[, h, w])``."""
    n = len(specs)
    if not isinstance(params, torch.Tensor):
        raise WiseError("parameters must be a torch.Tensor of shape (B, P) or (B, P, h, w)")
    if params.dim() == 1:
        params = params.unsqueeze(0)
    if params.dim() not in (2, 4) or params.shape[1] != n:
        raise WiseError(
            f"parameters must have shape (B, {n}) or (B, {n}, h, w) for the {n} parameters "
            f"{', '.join(s.name for s in specs)}; got {tuple(params.shape)}"
        )
    if params.shape[0] not in (1, batch):
        raise WiseError(f"parameters have batch size {params.shape[0]} but the image batch is {batch}")
    if params.shape[0] != batch:
        params = params.expand(batch, *params.shape[1:])
    return params


def resize_masks(masks: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """Resize ``(B, P, h, w)`` masks bilinearly to ``size`` = (H, W)."""
    if tuple(masks.shape[-2:]) == tuple(size):
        return masks
    return F.interpolate(masks, size=size, mode="bilinear", align_corners=False)


def real_maps(params: torch.Tensor, specs: Specs, size: tuple[int, int]) -> dict[str, torch.Tensor]:
    """Real-unit values by name, each ``(B, 1, 1, 1)`` (global) or ``(B, 1, H, W)`` (local)."""
    if params.dim() == 2:
        params = params[:, :, None, None]
    else:
        params = resize_masks(params, size)
    real = to_real(params, specs)
    return {s.name: real[:, i : i + 1] for i, s in enumerate(specs)}
