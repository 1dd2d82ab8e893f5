"""StatsNet: a small network that compares photo and example through global feature statistics."""

from __future__ import annotations

import torch
from torch import nn

from wise.ppn.heads import bounded

CHANNELS = (24, 48, 96, 128)
HIDDEN = 256


def _mean_and_deviation(x: torch.Tensor) -> torch.Tensor:
    """Per channel: the mean and the standard deviation over the picture, ``(B, 2C)``."""
    mean = x.mean(dim=(2, 3))
    deviation = (x.square().mean(dim=(2, 3)) - mean.square()).clamp_min(1e-8).sqrt()
    return torch.cat((mean, deviation), dim=1)


class StatsNet(nn.Module):
    """Four Conv-ReLU-MaxPool stages (24, 48, 96, 128 channels) on photo, example and their
    difference; each stage's channels summarized by their mean and standard deviation over the
    whole picture (statistics of a texture rather than a map of where it is, as in style
    transfer's Gram features); a two-layer head, ``tanh / 2``.

    The statistics make its features the same for a window of a picture as for the whole of
    it, so a network trained on windows predicts for whole pictures.

    ``forward(photo, example)``: two ``(B, 3, H, W)`` images in [0, 1] -> ``(B, P)`` normalized
    parameters in [-0.5, 0.5].
    """

    def __init__(self, params: int) -> None:
        super().__init__()
        stages, channels = [], 9
        for width in CHANNELS:
            stages.append(nn.Sequential(nn.Conv2d(channels, width, 3, padding=1), nn.ReLU(), nn.MaxPool2d(2)))
            channels = width
        self.stages = nn.ModuleList(stages)
        self.head = nn.Sequential(nn.Linear(2 * (9 + sum(CHANNELS)), HIDDEN), nn.ReLU(), nn.Linear(HIDDEN, params))

    def statistics(self, photo: torch.Tensor, example: torch.Tensor) -> torch.Tensor:
        """The mean and deviation of the inputs and of every stage: ``(B, 2 (9 + sum(CHANNELS)))``."""
        x = torch.cat((photo, example, example - photo), dim=1)
        features = [_mean_and_deviation(x)]
        for stage in self.stages:
            x = stage(x)
            features.append(_mean_and_deviation(x))
        return torch.cat(features, dim=1)

    def forward(self, photo: torch.Tensor, example: torch.Tensor) -> torch.Tensor:
        return bounded(self.head(self.statistics(photo, example)))
