"""SimpleNet: the smallest global parameter prediction network of the WISE supplement."""

from __future__ import annotations

import torch
from torch import nn

from wise.ppn.heads import bounded

CHANNELS = (16, 32, 64)
POOLED = 4
"""Each stage is averaged to POOLED x POOLED cells, so any input size gives the same features."""


class SimpleNet(nn.Module):
    """Three Conv-ReLU-MaxPool stages (16, 32, 64 channels) on photo and example concatenated
    along channels, their features concatenated, one linear layer, ``tanh / 2``.

    ``forward(photo, example)``: two ``(B, 3, H, W)`` images in [0, 1] -> ``(B, P)`` normalized
    parameters in [-0.5, 0.5].
    """

    def __init__(self, params: int) -> None:
        super().__init__()
        stages, channels = [], 6
        for width in CHANNELS:
            stages.append(nn.Sequential(nn.Conv2d(channels, width, 3, padding=1), nn.ReLU(), nn.MaxPool2d(2)))
            channels = width
        self.stages = nn.ModuleList(stages)
        self.pool = nn.AdaptiveAvgPool2d(POOLED)
        self.linear = nn.Linear(sum(CHANNELS) * POOLED * POOLED, params)

    def forward(self, photo: torch.Tensor, example: torch.Tensor) -> torch.Tensor:
        x, features = torch.cat((photo, example), dim=1), []
        for stage in self.stages:
            x = stage(x)
            features.append(self.pool(x).flatten(1))
        return bounded(self.linear(torch.cat(features, dim=1)))
