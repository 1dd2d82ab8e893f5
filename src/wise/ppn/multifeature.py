"""VGG-11 multi-feature + Gram + multi-head (WISE supplement, "Global PPN").

Photo and example pass through the same VGG-11 (Simonyan & Zisserman 2015) separately. At the
end of every convolution stage two compact descriptors are taken: a stride-4 4x4 convolution
(averaged to a fixed grid), and the Gram matrix of a 1x1 convolution's channels (the style
statistics of Gatys et al. 2016). All are concatenated for both images and read by one head
per parameter. The ``features`` layout is torchvision's ``vgg11``, so ImageNet weights in its
state-dict layout load with :func:`wise.ppn.weights.load_vgg11`.
"""

from __future__ import annotations

import torch
from torch import nn

from wise.ppn.heads import MultiHead

STAGES = ((64,), (128,), (256, 256), (512, 512), (512, 512))
"""Convolutions per stage of VGG-11 (configuration A), each stage ending in a max pool."""
COMPACT_CHANNELS = 8
COMPACT_GRID = 2
GRAM_CHANNELS = 16


def gram_matrix(features: torch.Tensor) -> torch.Tensor:
    """``(B, C, H, W)`` -> ``(B, C * C)``: channel correlations, normalized by ``H * W``."""
    b, c, h, w = features.shape
    flat = features.reshape(b, c, h * w)
    return (flat @ flat.transpose(1, 2) / (h * w)).reshape(b, c * c)


class MultiFeaturePPN(nn.Module):
    """``forward(photo, example)``: two ``(B, 3, H, W)`` images in [0, 1] (at least 32 pixels a
    side) -> ``(B, P)`` normalized parameters in [-0.5, 0.5]."""

    def __init__(self, params: int) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        self.stage_ends: list[int] = []
        channels = 3
        for stage in STAGES:
            for width in stage:
                layers += [nn.Conv2d(channels, width, 3, padding=1), nn.ReLU()]
                channels = width
            self.stage_ends.append(len(layers) - 1)
            layers.append(nn.MaxPool2d(2))
        self.features = nn.Sequential(*layers)
        widths = [stage[-1] for stage in STAGES]
        self.compact = nn.ModuleList(nn.Conv2d(w, COMPACT_CHANNELS, 4, stride=4) for w in widths)
        self.gram = nn.ModuleList(nn.Conv2d(w, GRAM_CHANNELS, 1) for w in widths)
        self.grid = nn.AdaptiveAvgPool2d(COMPACT_GRID)
        per_image = len(STAGES) * (COMPACT_CHANNELS * COMPACT_GRID**2 + GRAM_CHANNELS**2)
        self.heads = MultiHead(2 * per_image, params)

    def _compact(self, stage: int, x: torch.Tensor) -> torch.Tensor:
        """The stride-4 descriptor of a stage's output; outputs under 4 pixels are enlarged first."""
        if min(x.shape[-2:]) < 4:
            x = nn.functional.interpolate(x, size=(4, 4), mode="bilinear", align_corners=False)
        return self.grid(self.compact[stage](x)).flatten(1)

    def describe(self, image: torch.Tensor) -> torch.Tensor:
        """The concatenated descriptors of one batch of images, ``(B, F / 2)``."""
        found, x = [], image
        for index, layer in enumerate(self.features):
            x = layer(x)
            if index in self.stage_ends:
                stage = self.stage_ends.index(index)
                found += [self._compact(stage, x), gram_matrix(self.gram[stage](x))]
        return torch.cat(found, dim=1)

    def forward(self, photo: torch.Tensor, example: torch.Tensor) -> torch.Tensor:
        return self.heads(torch.cat((self.describe(photo), self.describe(example)), dim=1))
