"""Joint bilateral upsampling of a low-resolution result, guided by the full-resolution image."""

from __future__ import annotations

from typing import Callable, Sequence

import torch
import torch.nn.functional as F

from wise.errors import WiseError
from wise.filters import fused
from wise.filters._checks import ParamLike, as_map, check_image
from wise.filters.gaussian import MIN_SIGMA
from wise.filters.sampling import tap_sum

DEFAULT_SIGMA_RANGE = 0.1
"""Range sigma suited to a guide in [0, 1] such as RGB; about 10 suits CIE Lab (L in [0, 100])."""
MIN_SIGMA_SPATIAL = 0.25
"""Smallest spatial sigma (low-resolution pixels): the nearest neighbour's weight stays representable."""
RANGE_EXPONENT_FLOOR = -50.0
"""The range weight stops falling at exp(-50), so a pixel unlike all its neighbours falls back to
plain spatial weights instead of dividing zero by zero."""
EXPONENT_FLOOR = -80.0
"""Weights stop falling at exp(-80), above float32's denormals (slow) and far below any weight that matters."""
BAND_PIXELS = 1 << 17
"""Output pixels per row band when no gradient is needed: each band's temporaries stay in cache."""

TapFn = Callable[..., tuple[torch.Tensor, torch.Tensor]]
Gather = Callable[[Sequence[torch.Tensor], int, int], torch.Tensor]


def downsample(image: torch.Tensor, factor: float) -> torch.Tensor:
    """Area (box) downsampling by ``factor`` >= 1, any ratio; differentiable.

    Args:
        image: ``(B, C, H, W)``.
        factor: how many input pixels per output pixel along each axis.

    Returns:
        ``(B, C, max(1, round(H / factor)), max(1, round(W / factor)))``.
    """
    check_image(image)
    if not factor >= 1.0:
        raise WiseError(f"downsample factor must be >= 1, got {factor}")
    h, w = image.shape[-2:]
    return F.adaptive_avg_pool2d(image, (max(1, round(h / factor)), max(1, round(w / factor))))


def _axis_neighbours(out_size: int, low_size: int, radius: int, ref: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The ``2 * radius`` low-resolution neighbours of every output position along one axis.

    Output pixel centres map onto the low-resolution grid as in area downsampling
    (``u = (x + 0.5) * low / out - 0.5``); neighbour ``i`` is ``floor(u) + i`` for
    ``i`` in ``[1 - radius, radius]``, so the neighbours straddle ``u`` symmetrically.

    Returns:
        ``index`` ``(2 * radius, out_size)`` clamped into the low-resolution image (border
        replication) and ``distance_sq`` ``(2 * radius, out_size)``, the squared distance
        in low-resolution pixels from ``u`` to the unclamped neighbour.
    """
    position = (torch.arange(out_size, dtype=torch.float64, device=ref.device) + 0.5) * (low_size / out_size) - 0.5
    offsets = torch.arange(1 - radius, radius + 1, dtype=torch.float64, device=ref.device)
    neighbour = position.floor().unsqueeze(0) + offsets.unsqueeze(1)
    distance = neighbour - position.unsqueeze(0)
    index = neighbour.clamp(0, low_size - 1).long()
    return index, (distance * distance).to(ref.dtype)


def _make_tap(gather: Gather, n: int, rows_sq: torch.Tensor, cols_sq: torch.Tensor, channels: int) -> TapFn:
    """Tap ``k`` of the upsampling sum: neighbour ``(j, i) = divmod(k, n)`` of every output pixel.

    The tap's inputs are the low-resolution sources that ``gather(sources, j, i)`` turns
    into the neighbours ``(B, C + G, H, W)`` (the low-resolution result in the first
    ``channels`` channels, the downsampled guide in the others), then the guide and the
    two sigma terms.
    """

    def tap(k: int, *inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        *sources, guide, neg_inv_two_spatial_sq, neg_inv_two_range_sq = inputs
        j, i = divmod(k, n)
        neighbours = gather(sources, j, i)
        difference = guide - neighbours[:, channels:]
        range_sq = (difference * difference).sum(dim=1, keepdim=True)
        range_exponent = (range_sq * neg_inv_two_range_sq).clamp_min(RANGE_EXPONENT_FLOOR)
        spatial_sq = rows_sq[j].unsqueeze(1) + cols_sq[i].unsqueeze(0)
        exponent = torch.addcmul(range_exponent, spatial_sq, neg_inv_two_spatial_sq).clamp_min(EXPONENT_FLOOR)
        weight = torch.exp(exponent)
        return weight * neighbours[:, :channels], weight

    return tap


def _gather_pixels(rows: torch.Tensor, cols: torch.Tensor) -> Gather:
    """Neighbours straight from the low-resolution ``packed`` tensor (the only source)."""

    def gather(sources: Sequence[torch.Tensor], j: int, i: int) -> torch.Tensor:
        return sources[0].index_select(3, cols[i]).index_select(2, rows[j])

    return gather


def _gather_rows(rows: torch.Tensor) -> Gather:
    """Neighbours from sources already gathered at the output columns, one per column neighbour."""

    def gather(sources: Sequence[torch.Tensor], j: int, i: int) -> torch.Tensor:
        return sources[i].index_select(2, rows[j])

    return gather


def _rows(value: torch.Tensor, start: int, stop: int) -> torch.Tensor:
    return value if value.shape[-2] == 1 else value[..., start:stop, :]


def _upsample_in_bands(
    packed: torch.Tensor,
    guide: torch.Tensor,
    neg_s: torch.Tensor,
    neg_r: torch.Tensor,
    geometry: tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor],
    channels: int,
) -> torch.Tensor:
    """The same sum as the autograd path, a band of output rows at a time so that the
    temporaries stay in cache; the columns of the neighbours are gathered once (no gradient)."""
    rows, rows_sq, cols, cols_sq = geometry
    n = rows.shape[0]
    b, _, height, width = guide.shape
    column_gathered = [packed.index_select(3, index) for index in cols]
    out = guide.new_empty(b, channels, height, width)
    band = max(1, BAND_PIXELS // width)
    for start in range(0, height, band):
        stop = min(height, start + band)
        first, last = int(rows[0, start]), int(rows[-1, stop - 1])
        total, norm = tap_sum(
            _make_tap(_gather_rows(rows[:, start:stop] - first), n, rows_sq[:, start:stop], cols_sq, channels),
            n * n,
            *[gathered[:, :, first : last + 1] for gathered in column_gathered],
            guide[:, :, start:stop],
            _rows(neg_s, start, stop),
            _rows(neg_r, start, stop),
        )
        torch.div(total, norm, out=out[:, :, start:stop])
    return out


def joint_bilateral_upsample(
    low: torch.Tensor,
    guide: torch.Tensor,
    sigma_spatial: ParamLike = 1.0,
    sigma_range: ParamLike = DEFAULT_SIGMA_RANGE,
    radius: int = 2,
) -> torch.Tensor:
    """Joint bilateral upsampling (Kopf et al. 2007) of ``low`` to the size of ``guide``.

    Every output pixel ``p`` averages its ``(2 * radius)^2`` nearest low-resolution pixels
    ``q`` (border replicated), weighted by a spatial Gaussian of their distance in
    low-resolution pixels and a range Gaussian of ``||guide(p) - guide_low(q)||``, where
    ``guide_low`` is ``guide`` area-downsampled to the size of ``low``. Neighbours are
    exact low-resolution pixels (nearest sampling, no interpolation), so a low-resolution
    value is never mixed across an edge before the range weight sees it; the kernel is cut
    off at ``radius``. Any size ratio works. Gradients reach ``low``, ``guide`` and both
    sigmas; backward recomputes each neighbour instead of storing it. Without gradients
    the output is computed in bands of rows, which is several times faster on a CPU.

    Args:
        low: ``(B, C, h, w)`` result computed at low resolution.
        guide: ``(B, G, H, W)`` full-resolution image (e.g. RGB or Lab), ``H >= h``, ``W >= w``.
        sigma_spatial: in low-resolution pixels (so independent of the image size);
            float, ``(B,)`` or ``(B, 1, H, W)`` at the output resolution.
        sigma_range: in the guide's units; float, ``(B,)`` or ``(B, 1, H, W)``.
        radius: neighbours reach ``radius`` low-resolution pixels on each side.

    Returns:
        ``(B, C, H, W)``.
    """
    check_image(low, "low")
    check_image(guide, "guide")
    if low.shape[0] != guide.shape[0] or low.dtype != guide.dtype or low.device != guide.device:
        raise WiseError(f"low {tuple(low.shape)} and guide {tuple(guide.shape)} need the same batch, dtype and device")
    (h, w), (height, width) = low.shape[-2:], guide.shape[-2:]
    if height < h or width < w:
        raise WiseError(f"guide {tuple(guide.shape)} must be at least as large as low {tuple(low.shape)}")
    if radius < 1:
        raise WiseError(f"radius must be at least 1, got {radius}")

    neg_s = -0.5 / as_map(sigma_spatial, guide, "sigma_spatial").clamp_min(MIN_SIGMA_SPATIAL).square()
    neg_r = -0.5 / as_map(sigma_range, guide, "sigma_range").clamp_min(MIN_SIGMA).square()
    guide_low = F.adaptive_avg_pool2d(guide, (h, w))
    rows, rows_sq = _axis_neighbours(height, h, radius, guide)
    cols, cols_sq = _axis_neighbours(width, w, radius, guide)
    if fused.enabled(low, guide, neg_s, neg_r):
        from wise.filters.fused.upsample import JointBilateralSum

        geometry = (rows, rows_sq, cols, cols_sq)
        return JointBilateralSum.apply(
            low, guide_low, guide, neg_s, neg_r, *geometry, RANGE_EXPONENT_FLOOR, EXPONENT_FLOOR
        )
    packed = torch.cat((low, guide_low), dim=1)
    channels = low.shape[1]

    inputs = (packed, guide, neg_s, neg_r)
    if not (torch.is_grad_enabled() and any(x.requires_grad for x in inputs)):
        return _upsample_in_bands(*inputs, (rows, rows_sq, cols, cols_sq), channels)
    n = rows.shape[0]
    total, norm = tap_sum(_make_tap(_gather_pixels(rows, cols), n, rows_sq, cols_sq, channels), n * n, *inputs)
    return total / norm
