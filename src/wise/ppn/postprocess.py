"""Post-processing CNNs for image-to-image translation (WISE Sec. 5.2): the networks ``N`` in
``N(O(I, P_L(I)))`` that turn the effect's output into the artist's drawing.

- :class:`ResnetTranslator`: Johnson et al. 2016's image transformation network (as in pix2pix
  and CycleGAN: two halving convolutions, residual blocks, two doubling ones).
- :class:`UNetTranslator`: pix2pix's U-Net generator (Isola et al. 2017).

Both map ``(B, 3, H, W)`` in [0, 1] to ``(B, 3, H, W)`` in [0, 1] for any ``H, W`` (padded to
the multiple they need, cropped back), and normalize each picture on its own
(``InstanceNorm``), so that batches of one train and predict alike.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from wise.errors import WiseError
from wise.ppn.choices import POST_WIDTH

DEFAULT_WIDTH = POST_WIDTH
RESNET_BLOCKS = 9
"""Residual blocks of Johnson et al.'s network for 256-pixel pictures."""
UNET_DEPTH = 8
"""Halvings of pix2pix's U-Net for 256-pixel pictures (``unet_256``)."""
DROPOUT = 0.5
SLOPE = 0.2
"""Negative slope of the U-Net encoder's LeakyReLU (pix2pix's)."""


def _norm(channels: int) -> nn.Module:
    return nn.InstanceNorm2d(channels, affine=True)


def _to_signed(image: torch.Tensor) -> torch.Tensor:
    return image * 2.0 - 1.0


def _to_unit(signed: torch.Tensor) -> torch.Tensor:
    return (torch.tanh(signed) + 1.0) / 2.0


def _padded(image: torch.Tensor, multiple: int) -> tuple[torch.Tensor, tuple[int, int]]:
    """``image`` padded at the bottom and right to sides that are multiples of ``multiple``
    (reflected where the image is large enough, else replicated); the original size."""
    height, width = image.shape[-2:]
    padded = [max(math.ceil(side / multiple), 1) * multiple for side in (height, width)]
    pad_height, pad_width = padded[0] - height, padded[1] - width
    if pad_height == pad_width == 0:
        return image, (height, width)
    mode = "reflect" if max(pad_height, pad_width) < min(height, width) else "replicate"
    return F.pad(image, (0, pad_width, 0, pad_height), mode=mode), (height, width)


class _ResidualBlock(nn.Module):
    def __init__(self, channels: int, dropout: bool) -> None:
        super().__init__()
        layers: list[nn.Module] = [
            nn.Conv2d(channels, channels, 3, padding=1, padding_mode="reflect"),
            _norm(channels),
            nn.ReLU(True),
        ]
        if dropout:
            layers.append(nn.Dropout(DROPOUT))
        layers += [nn.Conv2d(channels, channels, 3, padding=1, padding_mode="reflect"), _norm(channels)]
        self.body = nn.Sequential(*layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.body(x)


class ResnetTranslator(nn.Module):
    """Johnson et al. 2016, "Perceptual Losses for Real-Time Style Transfer": a 7×7
    convolution of ``width`` channels, two stride-2 convolutions to four times the width,
    ``blocks`` residual blocks (dropout inside each with ``dropout``), two transposed
    convolutions back, a 7×7 convolution to RGB. ``(B, 3, H, W)`` -> ``(B, 3, H, W)``."""

    def __init__(self, width: int = DEFAULT_WIDTH, blocks: int = RESNET_BLOCKS, dropout: bool = False) -> None:
        super().__init__()
        if width < 1 or blocks < 0:
            raise WiseError(f"a ResNet translator needs a width of at least 1 and blocks >= 0, got {width}, {blocks}")
        self.width, self.blocks, self.dropout = width, blocks, dropout
        layers: list[nn.Module] = [
            nn.Conv2d(3, width, 7, padding=3, padding_mode="reflect"),
            _norm(width),
            nn.ReLU(True),
        ]
        for factor in (1, 2):
            layers += [
                nn.Conv2d(width * factor, width * factor * 2, 3, stride=2, padding=1),
                _norm(width * factor * 2),
                nn.ReLU(True),
            ]
        layers += [_ResidualBlock(width * 4, dropout) for _ in range(blocks)]
        for factor in (4, 2):
            layers += [
                nn.ConvTranspose2d(width * factor, width * factor // 2, 3, stride=2, padding=1, output_padding=1),
                _norm(width * factor // 2),
                nn.ReLU(True),
            ]
        layers.append(nn.Conv2d(width, 3, 7, padding=3, padding_mode="reflect"))
        self.layers = nn.Sequential(*layers)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        padded, (height, width) = _padded(image, 4)
        return _to_unit(self.layers(_to_signed(padded)))[..., :height, :width]


class _UNetLevel(nn.Module):
    """One level of pix2pix's U-Net: a halving convolution, the levels below, a doubling
    transposed convolution, and the level's input joined to its output (skip connection)."""

    def __init__(
        self, outer: int, inner: int, below: nn.Module | None, outermost: bool = False, dropout: bool = False
    ) -> None:
        super().__init__()
        innermost = below is None
        self.outermost = outermost
        down: list[nn.Module] = [] if outermost else [nn.LeakyReLU(SLOPE)]
        down.append(nn.Conv2d(outer, inner, 4, stride=2, padding=1))
        if not (outermost or innermost):
            down.append(_norm(inner))
        self.down = nn.Sequential(*down)
        self.below = below if below is not None else nn.Identity()
        up: list[nn.Module] = [
            nn.ReLU(True),
            nn.ConvTranspose2d(inner if innermost else inner * 2, outer, 4, stride=2, padding=1),
        ]
        if not outermost:
            up.append(_norm(outer))
            if dropout:
                up.append(nn.Dropout(DROPOUT))
        self.up = nn.Sequential(*up)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        made = self.up(self.below(self.down(x)))
        return made if self.outermost else torch.cat((x, made), dim=1)


class UNetTranslator(nn.Module):
    """pix2pix's U-Net generator (Isola et al. 2017, ``unet_256`` at ``depth`` 8): ``depth``
    stride-2 4×4 convolutions from ``width`` channels doubling up to eight times the width,
    transposed convolutions back, each level's input joined to its output; with ``dropout``,
    the three levels below the innermost drop half their features in training (pix2pix's
    noise). ``(B, 3, H, W)`` -> ``(B, 3, H, W)``."""

    def __init__(self, width: int = DEFAULT_WIDTH, depth: int = UNET_DEPTH, dropout: bool = False) -> None:
        super().__init__()
        if width < 1 or not 2 <= depth <= 9:
            raise WiseError(f"a U-Net translator needs a width of at least 1 and 2 to 9 levels, got {width}, {depth}")
        self.width, self.depth, self.dropout = width, depth, dropout
        channels = [width * min(2**level, 8) for level in range(depth)]
        level: nn.Module | None = None
        for index in reversed(range(1, depth)):
            # pix2pix's dropout: the three levels of eight times the width below the innermost
            noisy = dropout and depth - 4 <= index <= depth - 2 and channels[index - 1] == width * 8
            level = _UNetLevel(channels[index - 1], channels[index], level, dropout=noisy)
        self.top = _UNetLevel(3, channels[0], level, outermost=True)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        padded, (height, width) = _padded(image, 2**self.depth)
        return _to_unit(self.top(_to_signed(padded)))[..., :height, :width]


POST_NETWORKS: dict[str, type[nn.Module]] = {"resnet": ResnetTranslator, "unet": UNetTranslator}


def create_post(name: str, width: int = DEFAULT_WIDTH, dropout: bool = False) -> nn.Module:
    """A post-processing network by name (``resnet``, ``unet``) at its default depth."""
    if name not in POST_NETWORKS:
        raise WiseError(f"unknown post-processing network {name!r}; use one of {', '.join(POST_NETWORKS)}")
    return POST_NETWORKS[name](width=width, dropout=dropout)
