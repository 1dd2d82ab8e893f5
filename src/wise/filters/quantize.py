"""Colour quantization with a learnable number of bins.

Hard and soft (tanh) quantization after Winnemöller, Olsen & Gooch 2006, "Real-Time Video
Abstraction". The number of bins gets the numeric gradient of the WISE supplement
(Lötzsch et al. 2022, section "Color Quantization"), because the derivative of a staircase
with respect to its step count carries no useful information.
"""

from __future__ import annotations

import math

import torch

from wise.errors import WiseError
from wise.filters import fused
from wise.filters._checks import ParamLike, as_map, check_image
from wise.filters.smoothing import step_temperature

MIN_BINS = 1.0
"""Fewest bins used; smaller values are clamped (one bin maps everything to its centre)."""
SOFTNESS_FLOOR = 1e-4
"""Smallest softness of the tanh ramp; below it the ramp is a hard step in float precision."""
CANDIDATE_OFFSETS = (1 / 16, 1 / 8) + tuple(quarter / 4 for quarter in range(1, 25))
"""The numeric gradient tries the bin counts ``b - o`` and ``b + o`` (at least 1) for these
offsets ``o`` besides ``b`` itself: up to 6 bins away in quarter steps, because a count
scores well only within about a quarter bin of the target (every boundary ``k / b`` moves
with it), and finer steps near ``b`` to settle on a fractional count."""
SMOOTHED_SOFTNESS = 0.5
"""Softness (bin widths) added to the ramps at step temperature 1: the staircase becomes a
gentle wave whose outputs move with ``bins`` everywhere."""
SCORE_SAMPLES = 16384
"""Pixels per image that score the candidates (a regular subsample of larger images): the
score is a count of signs, and scoring every candidate on every pixel would cost more than
the rest of the backward pass."""


def _last_level(bins: torch.Tensor) -> torch.Tensor:
    # index of the top bin; with a fractional bin count the top bin is partial
    return torch.ceil(bins) - 1.0


def _hard_levels(x: torch.Tensor, bins: torch.Tensor) -> torch.Tensor:
    # in place on one fresh buffer: this runs once per candidate in the numeric gradient,
    # and never on tensors that autograd tracks
    index = torch.mul(x, bins).floor_().clamp_(min=0.0)
    index = torch.minimum(index, _last_level(bins), out=index)
    return index.add_(0.5).div_(bins)


def _soft_levels(x: torch.Tensor, bins: torch.Tensor, softness: torch.Tensor) -> torch.Tensor:
    # Winnemöller's ramp around the nearest inner bin boundary q:
    #   y = q + dq/2 * tanh(phi (x - q)) / tanh(phi dq/2),  dq = 1/b,  phi = b / softness,
    # computed in units of bin widths. Dividing by tanh(phi dq/2) (-> 1 for small softness)
    # makes y continuous at the bin centres and hit them exactly, so large softness tends
    # to the identity.
    scaled = x * bins
    boundary = torch.round(scaled.detach()).clamp_(min=1.0)
    boundary = torch.minimum(boundary, _last_level(bins).clamp_min(1.0), out=boundary)
    ramp = torch.tanh((scaled - boundary) / softness)
    return (boundary + ramp * (0.5 / torch.tanh(0.5 / softness))) / bins


def _levels(x: torch.Tensor, bins: torch.Tensor, softness: torch.Tensor | None) -> torch.Tensor:
    bins = bins.clamp_min(MIN_BINS)
    return _hard_levels(x, bins) if softness is None else _soft_levels(x, bins, softness)


def _candidate_steps() -> list[float | None]:
    # None stands for b itself, which scores 0 and wins when no bin count moves more
    # outputs downhill than uphill; the rest are ordered by size so ties go to the nearest.
    steps: list[float | None] = [None]
    for offset in CANDIDATE_OFFSETS:
        steps += [-offset, offset]
    return steps


def _candidate(bins: torch.Tensor, step: float | None) -> torch.Tensor:
    return bins if step is None else (bins + step).clamp_min(MIN_BINS)


def _subsample(tensor: torch.Tensor, stride: int) -> torch.Tensor:
    # every stride-th pixel of an image or map; (B, C, 1, 1) parameters stay as they are
    return tensor if tensor.shape[-1] == 1 else tensor[..., ::stride, ::stride]


def _best_bins(
    x: torch.Tensor, y: torch.Tensor, grad: torch.Tensor, bins: torch.Tensor, softness: torch.Tensor | None
) -> torch.Tensor:
    """``b_hat``, shaped like ``bins``: the candidate maximising, per image sharing ``bins``,
    f(r) = sum_i sign(y_i - q_r(x_i)) sign(g_i), the number of outputs that switching to
    ``r`` bins moves downhill (against their gradient) minus those it moves uphill."""
    steps = _candidate_steps()
    batch = grad.shape[0]
    stride = max(1, math.ceil(math.sqrt(x.shape[-2] * x.shape[-1] / SCORE_SAMPLES)))
    x, y, grad, sample_bins, softness = (
        _subsample(t, stride) if t is not None else None for t in (x, y, grad, bins, softness)
    )
    if fused.enabled(x, y, grad, sample_bins, *([] if softness is None else [softness])):
        from wise.filters.fused.quantize import candidate_scores

        offsets = [step for step in steps if step is not None]
        by_offset = iter(candidate_scores(x, y, grad, sample_bins, softness, offsets, MIN_BINS))
        scores = torch.stack([grad.new_zeros(batch) if step is None else next(by_offset) for step in steps])
    else:
        grad_sign = grad.sign().reshape(batch, -1, 1)

        def score(step: float | None) -> torch.Tensor:
            if step is None:
                return grad.new_zeros(batch)  # y itself
            levels = _levels(x, _candidate(sample_bins, step), softness)
            moves = torch.sub(y, levels, out=levels).sign_()
            return torch.bmm(moves.reshape(batch, 1, -1), grad_sign).view(batch)  # per-image dot product

        scores = torch.stack([score(k) for k in steps])
    if bins.shape[0] == 1:
        scores = scores.sum(dim=1, keepdim=True)  # one bin count shared by the whole batch
    best = scores.argmax(dim=0).tolist()
    return torch.cat([_candidate(bins[i : i + 1], steps[j]) for i, j in enumerate(best)])


class _NumericBinsGradient(torch.autograd.Function):
    """Passes ``y`` through unchanged and gives ``bins`` the numeric gradient of WISE:
    dL/db_i = |g_i| (b_i - b_hat), summed over the pixels (and channels) that share b."""

    @staticmethod
    def forward(ctx, y, bins, x, softness):  # type: ignore[override]
        ctx.save_for_backward(x, y.detach(), bins.detach(), softness)
        return y.view_as(y)

    @staticmethod
    def backward(ctx, grad):  # type: ignore[override]
        x, y, bins, softness = ctx.saved_tensors
        grad_bins = None
        if ctx.needs_input_grad[1]:
            best = _best_bins(x, y, grad, bins, softness)
            grad_map = grad.abs().sum(dim=1, keepdim=True) * (bins - best)
            if bins.shape[0] == 1:
                grad_map = grad_map.sum(dim=0, keepdim=True)
            if bins.shape[-2:] == (1, 1):
                grad_map = grad_map.sum(dim=(2, 3), keepdim=True)
            grad_bins = grad_map
        return grad, grad_bins, None, None


def quantize(image: torch.Tensor, bins: ParamLike, softness: ParamLike = 0.0) -> torch.Tensor:
    """Per-channel colour quantization into ``bins`` levels (Winnemöller et al. 2006).

    Hard (``softness`` 0): ``y = (floor(x b) + 0.5) / b`` with the index clamped to the
    ``ceil(b)`` bins covering [0, 1] (a fractional ``b`` makes the top bin partial).
    Soft (``softness`` > 0): ``y = q + (1/2b) tanh(phi (x - q)) / tanh(phi / 2b)`` with
    ``q`` the nearest inner bin boundary and ``phi = b / softness``: ``softness`` is about
    the half-width of the ramp around each boundary, in bin widths. It tends to the hard steps as
    ``softness -> 0`` and to the identity as it grows. Winnemöller's formula lacks the
    ``tanh(phi / 2b)`` normalisation, which is 1 for sharp ramps and otherwise keeps the
    output continuous at the bin centres.

    Gradients: the image gets the straight-through gradient (identity) in the hard variant
    and the true gradient in the soft one; ``softness`` its true gradient; ``bins`` the
    numeric gradient of the WISE supplement: with ``g = dL/dy``, ``b_hat`` maximises
    ``f(r) = sum_i sign(y_i - q_r(x_i)) sign(g_i)`` over ``b`` itself and
    ``r = b +- o`` for the offsets ``o`` of ``CANDIDATE_OFFSETS`` (evaluated with the same
    quantizer and softness), and ``dL/db = sum_i |g_i| (b - b_hat)`` (zero when no candidate
    beats ``b``). The paper leaves the candidates open; offsets from 1/16 to 6 bins reach a
    distant count in a few steps and still settle on a fractional one. A global or ``(B,)``
    ``b`` sums over its image(s). A per-pixel map (local version) scores the same offset at
    every pixel (``r_i = b_i + o``), picks the best offset per image and gets
    ``|g_i| (b_i - r_i)`` per pixel (``|g|`` summed over channels).

    Args:
        image: ``(B, C, H, W)`` values in [0, 1].
        bins: number of bins (>= 1, need not be an integer): a float, ``(B,)`` tensor or
            ``(B, 1, H, W)`` map.
        softness: >= 0: a float, ``(B,)`` tensor or ``(B, 1, H, W)`` map. A float 0 gives
            hard steps; a tensor always takes the soft path (floored at ``SOFTNESS_FLOOR``).
            A step temperature ``t > 0`` (:func:`wise.filters.smoothing.smoothed_steps`)
            adds ``SMOOTHED_SOFTNESS * t``.

    Returns:
        ``(B, C, H, W)`` quantized image.
    """
    check_image(image)
    if not isinstance(bins, torch.Tensor) and bins < MIN_BINS:
        raise WiseError(f"bins must be at least {MIN_BINS:g}, got {bins:g}")
    if not isinstance(softness, torch.Tensor) and softness < 0.0:
        raise WiseError(f"softness must be >= 0, got {softness:g}")
    bins_map = as_map(bins, image, "bins")
    detached_bins = bins_map.detach()
    temperature = step_temperature()
    if isinstance(softness, torch.Tensor) or softness > 0.0 or temperature > 0.0:
        softness_map = as_map(softness, image, "softness")
        if temperature > 0.0:
            softness_map = softness_map + SMOOTHED_SOFTNESS * temperature
        softness_map = softness_map.clamp_min(SOFTNESS_FLOOR)
        output = _levels(image, detached_bins, softness_map)
        numeric_softness = softness_map.detach()
    else:
        output = _levels(image.detach(), detached_bins, None)
        if image.requires_grad:
            output = output + (image - image.detach())  # straight-through: dy/dx = 1
        numeric_softness = None
    if not bins_map.requires_grad:
        return output
    return _NumericBinsGradient.apply(output, bins_map, image.detach(), numeric_softness)
