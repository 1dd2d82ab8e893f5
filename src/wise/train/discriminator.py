"""The conditional PatchGAN discriminator of pix2pix (Isola et al. 2017) and its losses."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from wise.errors import WiseError
from wise.train.choices import GAN_LOSSES

DEFAULT_WIDTH = 64
SLOPE = 0.2
LAYERS = 3
"""Strided layers: with 4×4 kernels, three of them and two more layers see 70×70 pixels."""


class PatchDiscriminator(nn.Module):
    """Judges every 70×70 patch of an image as real or made, given the photo it was made
    from (the pair concatenated: a conditional GAN).

    C``w``-C``2w``-C``4w``-C``8w`` 4×4 convolutions (strides 2, 2, 2, 1; instance-normalized
    after the first; LeakyReLU 0.2), then one 4×4 convolution to one logit per patch.

    ``forward(photo, image)``: two ``(B, 3, H, W)`` images -> ``(B, 1, h, w)`` logits
    (h ≈ H / 8 - 2).
    """

    def __init__(self, width: int = DEFAULT_WIDTH) -> None:
        super().__init__()
        if width < 1:
            raise WiseError(f"the discriminator's width must be at least 1, got {width}")
        layers: list[nn.Module] = [nn.Conv2d(6, width, 4, stride=2, padding=1), nn.LeakyReLU(SLOPE)]
        channels = width
        for layer in range(1, LAYERS + 1):
            out = width * min(2**layer, 8)
            stride = 2 if layer < LAYERS else 1
            layers += [
                nn.Conv2d(channels, out, 4, stride=stride, padding=1, bias=False),
                nn.InstanceNorm2d(out, affine=True),
                nn.LeakyReLU(SLOPE),
            ]
            channels = out
        layers.append(nn.Conv2d(channels, 1, 4, stride=1, padding=1))
        self.layers = nn.Sequential(*layers)

    def forward(self, photo: torch.Tensor, image: torch.Tensor) -> torch.Tensor:
        return self.layers(torch.cat((photo, image), dim=1))


def adversarial_loss(kind: str, logits: torch.Tensor, real: bool) -> torch.Tensor:
    """The GAN loss of ``logits`` for the label ``real``: least squares (LSGAN, Mao et al.
    2017) or the vanilla binary cross-entropy of Goodfellow et al. 2014."""
    if kind not in GAN_LOSSES:
        raise WiseError(f"unknown GAN loss {kind!r}; use one of {', '.join(GAN_LOSSES)}")
    label = torch.full_like(logits, 1.0 if real else 0.0)
    if kind == "lsgan":
        return F.mse_loss(logits, label)
    return F.binary_cross_entropy_with_logits(logits, label)
