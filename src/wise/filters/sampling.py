"""Sampling an image at per-pixel offsets, and sums over such samples that recompute in backward.

The structure-adaptive filters of the paper (orientation-aligned bilateral, DoG and
line integral along a flow field) take, for every pixel, a fixed number of samples at
offsets that depend on the content. A naive autograd implementation keeps every sample
and every weight for backward, which costs ``samples x channels x pixels`` floats per
filter. :func:`tap_sum` keeps only the filter's inputs and recomputes one sample at a
time during backward, so memory stays at a few image-sized tensors whatever the number
of samples.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Callable, Sequence

import torch
import torch.nn.functional as F

TapFn = Callable[..., Sequence[torch.Tensor]]


@lru_cache(maxsize=16)
def _identity_grid(height: int, width: int, device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    ys = torch.linspace(-1.0, 1.0, height, device=device, dtype=dtype)
    xs = torch.linspace(-1.0, 1.0, width, device=device, dtype=dtype)
    return torch.stack(torch.meshgrid(xs, ys, indexing="xy"), dim=-1).unsqueeze(0)


def offset_grid(offset: torch.Tensor) -> torch.Tensor:
    """Sampling grid ``(B, H, W, 2)`` for :func:`torch.nn.functional.grid_sample`.

    Args:
        offset: ``(B, 2, H, W)`` displacement (x, y) in pixels from each pixel centre.
    """
    _, _, h, w = offset.shape
    base = _identity_grid(h, w, offset.device, offset.dtype)
    to_normalized = offset.new_tensor([2.0 / max(w - 1, 1), 2.0 / max(h - 1, 1)])
    return torch.addcmul(base, offset.permute(0, 2, 3, 1), to_normalized)


def sample_at_grid(image: torch.Tensor, grid: torch.Tensor) -> torch.Tensor:
    """Bilinear sample of ``image`` (B, C, H, W) on a grid from :func:`offset_grid`, border clamped."""
    if grid.shape[0] != image.shape[0]:
        grid = grid.expand(image.shape[0], *grid.shape[1:])
    return F.grid_sample(image, grid, mode="bilinear", padding_mode="border", align_corners=True)


def sample(image: torch.Tensor, offset: torch.Tensor) -> torch.Tensor:
    """Bilinear sample of ``image`` (B, C, H, W) at ``offset`` (B, 2, H, W) pixels, border clamped."""
    return sample_at_grid(image, offset_grid(offset))


class _TapSum(torch.autograd.Function):
    @staticmethod
    def forward(ctx, tap_fn: TapFn, n_taps: int, *inputs: torch.Tensor):  # type: ignore[override]
        sums: list[torch.Tensor] | None = None
        for k in range(n_taps):
            terms = tap_fn(k, *inputs)
            sums = list(terms) if sums is None else [s + t for s, t in zip(sums, terms)]
        assert sums is not None
        ctx.tap_fn = tap_fn
        ctx.n_taps = n_taps
        ctx.save_for_backward(*inputs)
        return tuple(sums)

    @staticmethod
    def backward(ctx, *grad_sums: torch.Tensor):  # type: ignore[override]
        inputs = ctx.saved_tensors
        wanted = ctx.needs_input_grad[2:]
        leaves = [x.detach().requires_grad_(w) for x, w in zip(inputs, wanted)]
        targets = [x for x, w in zip(leaves, wanted) if w]
        grads: list[torch.Tensor | None] = [None] * len(targets)
        with torch.enable_grad():
            for k in range(ctx.n_taps):
                terms = ctx.tap_fn(k, *leaves)
                outputs = [t for t in terms if t.requires_grad]
                upstream = [g for t, g in zip(terms, grad_sums) if t.requires_grad]
                if not outputs:
                    continue
                tap_grads = torch.autograd.grad(outputs, targets, upstream, allow_unused=True)
                for i, g in enumerate(tap_grads):
                    if g is not None:
                        grads[i] = g if grads[i] is None else grads[i].add_(g)
        it = iter(grads)
        return (None, None, *[next(it) if w else None for w in wanted])


def tap_sum(tap_fn: TapFn, n_taps: int, *inputs: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """``sum_k tap_fn(k, *inputs)`` for ``k < n_taps``, elementwise per returned tensor.

    ``tap_fn`` must be a pure function of its tensor inputs (captured Python values are
    fine) returning a tuple of tensors. Backward recomputes each tap, so no per-tap
    tensor is kept between forward and backward.
    """
    if not torch.is_grad_enabled() or not any(x.requires_grad for x in inputs):
        sums: list[torch.Tensor] | None = None
        with torch.no_grad():
            for k in range(n_taps):
                terms = tap_fn(k, *inputs)
                sums = [t.clone() for t in terms] if sums is None else [s.add_(t) for s, t in zip(sums, terms)]
        assert sums is not None
        return tuple(sums)
    return _TapSum.apply(tap_fn, n_taps, *inputs)


def sample_backward(
    grad_value: torch.Tensor, image: torch.Tensor, grid: torch.Tensor, need_image: bool
) -> tuple[torch.Tensor | None, torch.Tensor]:
    """Gradients of :func:`sample_at_grid` for the custom backward passes of the filters.

    Returns the gradient for ``image`` (``None`` unless ``need_image``) and the gradient for
    the sampling offset in pixels, ``(B, 2, H, W)``.
    """
    _, _, h, w = image.shape
    g_image, g_grid = torch.ops.aten.grid_sampler_2d_backward(grad_value, image, grid, 0, 1, True, [need_image, True])
    pixels_per_grid_unit = grad_value.new_tensor([2.0 / max(w - 1, 1), 2.0 / max(h - 1, 1)]).view(1, 2, 1, 1)
    return (g_image if need_image else None), g_grid.permute(0, 3, 1, 2) * pixels_per_grid_unit


def sum_to(grad: torch.Tensor, shape: torch.Size) -> torch.Tensor:
    """Sum a gradient over the dimensions that were broadcast from ``shape``."""
    dims = [i for i, (g, s) in enumerate(zip(grad.shape, shape)) if s == 1 and g != 1]
    return grad.sum(dim=dims, keepdim=True) if dims else grad
