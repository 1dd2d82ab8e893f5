"""LocalPPN: a U-Net that paints one mask per effect parameter from the photo alone."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from wise.errors import WiseError
from wise.ppn.heads import bounded

DEFAULT_DEPTH = 6
DEFAULT_WIDTH = 16
DEFAULT_MAX_WIDTH = 64
GROUPS = 8
"""Channels of a level are normalized in groups of this many (GroupNorm): the statistics do
not depend on the batch, so training with batches of one and predicting behave alike."""
SLOPE = 0.2
"""Negative slope of the LeakyReLU activations (pix2pix's)."""
START_WEIGHT_SCALE = 0.01
"""The output layer's initial weights are shrunk by this, so that an untrained network paints
nearly its start values whatever the photo (training still moves them: Adam's steps do not
depend on the size of a gradient)."""
START_BOUND = 0.45
"""Start values are kept within ±0.45 (5 % of the range from its ends): at the ends ``tanh``
saturates and its gradient vanishes, so training could not move a mask away from them."""


def _block(channels_in: int, channels_out: int, stride: int) -> nn.Sequential:
    """Two 3×3 convolutions, each normalized and activated; the first may halve the size."""
    return nn.Sequential(
        nn.Conv2d(channels_in, channels_out, 3, stride=stride, padding=1, padding_mode="reflect"),
        nn.GroupNorm(min(GROUPS, channels_out), channels_out),
        nn.LeakyReLU(SLOPE),
        nn.Conv2d(channels_out, channels_out, 3, padding=1, padding_mode="reflect"),
        nn.GroupNorm(min(GROUPS, channels_out), channels_out),
        nn.LeakyReLU(SLOPE),
    )


class LocalPPN(nn.Module):
    """Local parameter prediction network (WISE Sec. 4.1, "Local Parameter Prediction"): a
    U-Net (Ronneberger et al. 2015) from the photo to the effect's parameter masks.

    ``depth`` levels; the first works at half the photo's resolution with ``width`` channels,
    each further level halves the size and doubles the channels up to ``max_width``. The
    decoder enlarges bilinearly and joins each level's features (skip connections); a 1×1
    convolution gives one channel per parameter, ``tanh / 2``, enlarged bilinearly to the
    photo's size. Parameter masks are smooth, and a first level at full resolution would cost
    four times as much for detail the masks do not have. Sides that are not multiples of
    ``2 ** depth`` (or smaller than ``2 ** (depth + 1)``) are padded and the masks cropped back.

    ``start`` (``(P,)`` normalized parameters, e.g. a preset) sets the output layer so that an
    untrained network paints ``start`` everywhere: training departs from the look it knows.

    ``forward(photo)``: ``(B, 3, H, W)`` in [0, 1] -> ``(B, P, H, W)`` in [-0.5, 0.5].
    """

    def __init__(
        self,
        params: int,
        depth: int = DEFAULT_DEPTH,
        width: int = DEFAULT_WIDTH,
        max_width: int = DEFAULT_MAX_WIDTH,
        start: torch.Tensor | None = None,
    ) -> None:
        super().__init__()
        if params < 1:
            raise WiseError(f"a network must predict at least one parameter, got {params}")
        if not 2 <= depth <= 9:
            raise WiseError(f"the U-Net's depth must be from 2 to 9 levels, got {depth}")
        if not 1 <= width <= max_width:
            raise WiseError(f"the U-Net's width {width} must be from 1 to its largest width {max_width}")
        self.depth, self.width, self.max_width = depth, width, max_width
        channels = [min(width * 2**level, max_width) for level in range(depth)]
        self.encoder = nn.ModuleList(
            _block(3 if level == 0 else channels[level - 1], channels[level], 2) for level in range(depth)
        )
        self.decoder = nn.ModuleList(
            _block(channels[level + 1] + channels[level], channels[level], 1) for level in reversed(range(depth - 1))
        )
        self.head = nn.Conv2d(channels[0], params, 1)
        self.set_start(torch.zeros(params) if start is None else start)

    @torch.no_grad()
    def set_start(self, start: torch.Tensor) -> None:
        """Make the output layer paint ``start`` (``(P,)`` normalized) wherever its input is small."""
        values = start.detach().reshape(-1).to(self.head.bias).clamp(-START_BOUND, START_BOUND)
        if values.numel() != self.head.out_channels:
            raise WiseError(f"start values for {self.head.out_channels} parameters expected, got {values.numel()}")
        self.head.bias.copy_(torch.atanh(2.0 * values))
        self.head.weight.mul_(START_WEIGHT_SCALE)

    def forward(self, photo: torch.Tensor) -> torch.Tensor:
        height, width = photo.shape[-2:]
        multiple = 2**self.depth
        # Every level needs at least two pixels a side for the convolutions' reflection.
        padded_height, padded_width = (max(math.ceil(side / multiple), 2) * multiple for side in (height, width))
        x = photo
        if (padded_height, padded_width) != (height, width):
            # Reflection needs the pad below the side; replicate covers very small inputs.
            mode = "reflect" if max(padded_height - height, padded_width - width) < min(height, width) else "replicate"
            x = F.pad(x, (0, padded_width - width, 0, padded_height - height), mode=mode)
        skips = []
        for block in self.encoder:
            x = block(x)
            skips.append(x)
        x = skips.pop()
        for block in self.decoder:
            skip = skips.pop()
            x = F.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
            x = block(torch.cat((x, skip), dim=1))
        masks = bounded(self.head(x))
        masks = F.interpolate(masks, size=(padded_height, padded_width), mode="bilinear", align_corners=False)
        return masks[..., :height, :width]
