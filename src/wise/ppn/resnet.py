"""ResNet-50 without BatchNorm and a head per parameter (WISE supplement, "Global PPN").

The layout follows torchvision's ``resnet50`` (He et al. 2016), so ImageNet weights in its
state-dict layout load with :func:`wise.ppn.weights.load_resnet50`: each BatchNorm is folded
into the convolution before it, which then has a bias.
"""

from __future__ import annotations

import torch
from torch import nn

from wise.ppn.heads import MultiHead

BLOCKS = (3, 4, 6, 3)
WIDTHS = (64, 128, 256, 512)
EXPANSION = 4
FEATURES = WIDTHS[-1] * EXPANSION


class Bottleneck(nn.Module):
    """1x1, 3x3 (with the stride), 1x1 convolutions with ReLU and a residual connection."""

    def __init__(self, channels: int, width: int, stride: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(channels, width, 1)
        self.conv2 = nn.Conv2d(width, width, 3, stride=stride, padding=1)
        self.conv3 = nn.Conv2d(width, width * EXPANSION, 1)
        needs_projection = stride != 1 or channels != width * EXPANSION
        self.downsample = nn.Conv2d(channels, width * EXPANSION, 1, stride=stride) if needs_projection else None
        self.relu = nn.ReLU()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = self.relu(self.conv1(x))
        out = self.relu(self.conv2(out))
        out = self.conv3(out)
        return self.relu(out + (x if self.downsample is None else self.downsample(x)))


class ResNetPPN(nn.Module):
    """Photo and example concatenated along channels (6 in), ResNet-50 without BatchNorm, the
    features after the last convolution averaged, then :class:`~wise.ppn.heads.MultiHead`.

    ``forward(photo, example)``: two ``(B, 3, H, W)`` images in [0, 1] -> ``(B, P)`` in [-0.5, 0.5].
    """

    def __init__(self, params: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(6, WIDTHS[0], 7, stride=2, padding=3)
        self.relu = nn.ReLU()
        self.maxpool = nn.MaxPool2d(3, stride=2, padding=1)
        channels = WIDTHS[0]
        for index, (blocks, width) in enumerate(zip(BLOCKS, WIDTHS)):
            layer = []
            for block in range(blocks):
                stride = 2 if block == 0 and index > 0 else 1
                layer.append(Bottleneck(channels, width, stride))
                channels = width * EXPANSION
            setattr(self, f"layer{index + 1}", nn.Sequential(*layer))
        self.pool = nn.AdaptiveAvgPool2d(1)
        self.heads = MultiHead(FEATURES, params)

    def forward(self, photo: torch.Tensor, example: torch.Tensor) -> torch.Tensor:
        x = self.maxpool(self.relu(self.conv1(torch.cat((photo, example), dim=1))))
        for index in range(len(BLOCKS)):
            x = getattr(self, f"layer{index + 1}")(x)
        return self.heads(self.pool(x).flatten(1))
