"""Output layers shared by the parameter prediction networks."""

from __future__ import annotations

import torch
from torch import nn

HEAD_WIDTH = 256
"""Width of the hidden layers of each parameter's head."""


def bounded(x: torch.Tensor) -> torch.Tensor:
    """Normalized parameters in [-0.5, 0.5]: ``tanh(x) / 2`` (WISE supplement)."""
    return 0.5 * torch.tanh(x)


class MultiHead(nn.Module):
    """One small network per parameter (three linear layers, ReLU between), each reading the
    whole feature vector: ``(B, F) -> (B, P)`` in [-0.5, 0.5]."""

    def __init__(self, features: int, params: int, width: int = HEAD_WIDTH) -> None:
        super().__init__()
        self.heads = nn.ModuleList(
            nn.Sequential(
                nn.Linear(features, width), nn.ReLU(), nn.Linear(width, width), nn.ReLU(), nn.Linear(width, 1)
            )
            for _ in range(params)
        )

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        return bounded(torch.cat([head(features) for head in self.heads], dim=1))
