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

import importlib
from typing import Any

from wise.ppn.choices import ARCHITECTURE_NAMES, LOCAL_ARCHITECTURE_NAMES

# PyTorch loads with the first network asked for, not with the package: the commands check their
# arguments against wise.ppn.choices before that.
_LAZY = {
    "ARCHITECTURES": "wise.ppn.registry",
    "LOCAL_ARCHITECTURES": "wise.ppn.registry",
    "create": "wise.ppn.registry",
    "create_local": "wise.ppn.registry",
    "LocalPPN": "wise.ppn.unet",
    "MultiFeaturePPN": "wise.ppn.multifeature",
    "ResNetPPN": "wise.ppn.resnet",
    "SimpleNet": "wise.ppn.simple",
    "StatsNet": "wise.ppn.stats",
    "ToneNet": "wise.ppn.tone",
}


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module 'wise.ppn' has no attribute {name!r}")
    return getattr(importlib.import_module(_LAZY[name]), name)


def __dir__() -> list[str]:
    return sorted((*globals(), *_LAZY))


__all__ = ["ARCHITECTURE_NAMES", "LOCAL_ARCHITECTURE_NAMES", *_LAZY]
