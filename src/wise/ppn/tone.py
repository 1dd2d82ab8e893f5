"""ToneNet: StatsNet with what an example of a whitebox effect shows in closed form.

The colour adjustments of an effect map each colour of the photo to a colour of the example, so
the example's colours as a function of the photo's (its tone curves) say how bright, how
contrasted and how warm the look is more directly than statistics of either picture alone. A
quantized look puts its luminance on plateaus spaced ``1 / bins`` apart, which the comb of its
histogram shows (:mod:`wise.optimize.inversion` reads the same). Both are computed from the
pictures without learned weights and given to the head beside the convolution statistics.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from wise.filters.color import rgb_to_lab
from wise.ppn.heads import bounded
from wise.ppn.stats import CHANNELS, HIDDEN, StatsNet

CURVE_POINTS = 16
"""Points of each tone curve, evenly spread over the photo's values from 0 to 1."""
HISTOGRAM_BINS = 64
"""Bins of the example's luminance histogram given to the head."""
COMB_RESOLUTION = 1024
"""Bins of the finer luminance histogram the comb is scored on."""
COMB_COUNTS = tuple(2.0 + 0.25 * k for k in range(57))
"""Level counts 2-16 whose comb ``cos(2 pi (L n - 1/2))`` is scored against the example."""
TONE_FEATURES = 8 * CURVE_POINTS + HISTOGRAM_BINS + 2 * len(COMB_COUNTS)


def _soft_bins(values: torch.Tensor, points: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Linear interpolation weights of ``values`` ``(B, N)`` in [0, 1] onto ``points`` evenly spread
    points: the lower point's index, its weight, and the upper point's weight."""
    position = values.clamp(0.0, 1.0) * (points - 1)
    lower = position.floor().clamp(max=points - 2)
    upper_weight = position - lower
    return lower.long(), 1.0 - upper_weight, upper_weight


def _scatter(index: torch.Tensor, lower_w: torch.Tensor, upper_w: torch.Tensor, points: int) -> torch.Tensor:
    """Sums of the weights per point: ``(B, points)``."""
    total = index.new_zeros(index.shape[0], points, dtype=lower_w.dtype)
    total.scatter_add_(1, index, lower_w)
    total.scatter_add_(1, index + 1, upper_w)
    return total


def conditional_curves(given: torch.Tensor, values: torch.Tensor, points: int = CURVE_POINTS) -> torch.Tensor:
    """The mean of each row of ``values`` ``(B, V, N)`` over the pixels where ``given`` ``(B, N)``
    lies near each of ``points`` values from 0 to 1: ``(B, V, points)``; a point no pixel lies
    near takes the mean over all pixels."""
    index, lower_w, upper_w = _soft_bins(given, points)
    weight = _scatter(index, lower_w, upper_w, points)
    curves = []
    for row in values.unbind(dim=1):
        summed = _scatter(index, lower_w * row, upper_w * row, points)
        overall = row.mean(dim=1, keepdim=True)
        curves.append(torch.where(weight > 1e-3, summed / weight.clamp_min(1e-3), overall))
    return torch.stack(curves, dim=1)


def luminance_histogram(luminance: torch.Tensor, bins: int) -> torch.Tensor:
    """Share of the pixels per bin of ``luminance`` ``(B, N)`` in [0, 1], linearly interpolated:
    ``(B, bins)`` summing to 1."""
    index, lower_w, upper_w = _soft_bins(luminance, bins)
    return _scatter(index, lower_w, upper_w, bins) / luminance.shape[1]


def comb_scores(luminance: torch.Tensor) -> torch.Tensor:
    """For each count ``n`` of :data:`COMB_COUNTS`: the mean of ``cos(2 pi (L n - 1/2))`` over the
    pixels (1 where every value sits on a level centre ``(k + 1/2) / n``) and the magnitude of the
    comb at any phase: ``(B, 2 len(COMB_COUNTS))``."""
    histogram = luminance_histogram(luminance, COMB_RESOLUTION)
    centres = torch.linspace(0.0, 1.0, COMB_RESOLUTION, device=luminance.device, dtype=luminance.dtype)
    counts = torch.tensor(COMB_COUNTS, device=luminance.device, dtype=luminance.dtype)
    phase = 2.0 * math.pi * (centres[None, :] * counts[:, None] - 0.5)  # (counts, bins)
    cosine = histogram @ torch.cos(phase).T
    sine = histogram @ torch.sin(phase).T
    return torch.cat((cosine, torch.sqrt(cosine.square() + sine.square())), dim=1)


def tone_features(photo: torch.Tensor, example: torch.Tensor) -> torch.Tensor:
    """What the head of :class:`ToneNet` reads besides the convolutions, from photo and example
    ``(B, 3, H, W)`` in [0, 1]: ``(B, TONE_FEATURES)``.

    - the example's L*, a*, b* (scaled to about [-1, 1]) against the photo's L*, the spread of the
      example's L* there, and the square root of the share of the photo's pixels that lie there;
    - each of the example's R, G, B channels against the photo's same channel;
    - the square roots of the example's L* histogram and the comb scores of its levels (:func:`comb_scores`).
    """
    batch = photo.shape[0]
    with torch.no_grad():
        photo, example = photo.detach().float().clamp(0.0, 1.0), example.detach().float().clamp(0.0, 1.0)
        photo_l = (rgb_to_lab(photo)[:, 0] / 100.0).reshape(batch, -1)
        example_lab = rgb_to_lab(example).reshape(batch, 3, -1) / 100.0
        example_l = example_lab[:, 0]
        lab_curves = conditional_curves(photo_l, torch.cat((example_lab, example_l[:, None].square()), dim=1))
        spread = (lab_curves[:, 3] - lab_curves[:, 0].square()).clamp_min(0.0).sqrt()
        # square roots of the shares: the one or two spikes of a flat or black-and-white example
        # stay within [0, 1] like the other features rather than outweighing them
        occupancy = luminance_histogram(photo_l, CURVE_POINTS).sqrt()
        channel_curves = [
            conditional_curves(photo[:, c].reshape(batch, -1), example[:, c].reshape(batch, 1, -1))[:, 0]
            for c in range(3)
        ]
        histogram = luminance_histogram(example_l, HISTOGRAM_BINS).sqrt()
        features = [lab_curves[:, :3].flatten(1), spread, occupancy, *channel_curves, histogram, comb_scores(example_l)]
        return torch.cat(features, dim=1)


class ToneNet(StatsNet):
    """:class:`StatsNet` whose head also reads :func:`tone_features`: the tone curves from the
    photo's colours to the example's and the comb of the example's levels, the quantities a
    whitebox effect's colour adjustments and steps leave in closed form.

    ``forward(photo, example)``: two ``(B, 3, H, W)`` images in [0, 1] -> ``(B, P)`` normalized
    parameters in [-0.5, 0.5].
    """

    def __init__(self, params: int) -> None:
        super().__init__(params)
        statistics = 2 * (9 + sum(CHANNELS))
        self.head = nn.Sequential(nn.Linear(statistics + TONE_FEATURES, HIDDEN), nn.ReLU(), nn.Linear(HIDDEN, params))

    def forward(self, photo: torch.Tensor, example: torch.Tensor) -> torch.Tensor:
        statistics = self.statistics(photo, example)
        tones = tone_features(photo, example).to(statistics.dtype)
        return bounded(self.head(torch.cat((statistics, tones), dim=1)))
