"""Parameter prediction networks (WISE Sec. 4 and the supplement's "Global PPN"): plain
``nn.Module`` s that map a photo and a stylized example of it to an effect's normalized global
parameters in [-0.5, 0.5]. No training loop here (see :mod:`wise.train`).

- :class:`SimpleNet`: three convolution stages, one linear layer.
- :class:`StatsNet`: four convolution stages summarized by global mean and deviation, a
  two-layer head.
- :class:`ToneNet`: StatsNet whose head also reads the tone curves from photo to example and
  the comb of the example's levels, computed without learned weights.
- :class:`ResNetPPN`: ResNet-50 without BatchNorm on both images concatenated, a head per parameter.
- :class:`MultiFeaturePPN`: VGG-11 on each image, compact and Gram features of every stage, a
  head per parameter.

Local networks paint a mask per parameter from the photo alone (Sec. 4.1, "Local Parameter
Prediction"):

- :class:`LocalPPN`: a U-Net.

Backbones start from random weights or from ImageNet weights the user provides
(:mod:`wise.ppn.weights`).
"""

from __future__ import annotations

from torch import nn

from wise.errors import WiseError
from wise.ppn.multifeature import MultiFeaturePPN
from wise.ppn.resnet import ResNetPPN
from wise.ppn.simple import SimpleNet
from wise.ppn.stats import StatsNet
from wise.ppn.tone import ToneNet
from wise.ppn.unet import LocalPPN

ARCHITECTURES: dict[str, type[nn.Module]] = {
    "simple": SimpleNet,
    "stats": StatsNet,
    "tone": ToneNet,
    "resnet": ResNetPPN,
    "multifeature": MultiFeaturePPN,
}

LOCAL_ARCHITECTURES: dict[str, type[nn.Module]] = {"unet": LocalPPN}


def create(architecture: str, params: int) -> nn.Module:
    """A network by name (a key of :data:`ARCHITECTURES`) predicting ``params`` values."""
    if architecture not in ARCHITECTURES:
        raise WiseError(f"unknown architecture {architecture!r}; use one of {', '.join(ARCHITECTURES)}")
    if params < 1:
        raise WiseError(f"a network must predict at least one parameter, got {params}")
    return ARCHITECTURES[architecture](params)


def create_local(architecture: str, params: int, **options: int) -> nn.Module:
    """A local network by name (``unet``) painting ``params`` masks; ``options`` are its
    constructor's (e.g. ``depth``, ``width``, ``max_width``)."""
    if architecture not in LOCAL_ARCHITECTURES:
        raise WiseError(f"unknown local architecture {architecture!r}; use one of {', '.join(LOCAL_ARCHITECTURES)}")
    return LOCAL_ARCHITECTURES[architecture](params, **options)


__all__ = [
    "ARCHITECTURES",
    "LOCAL_ARCHITECTURES",
    "LocalPPN",
    "MultiFeaturePPN",
    "ResNetPPN",
    "SimpleNet",
    "StatsNet",
    "ToneNet",
    "create",
    "create_local",
]
