"""The architectures by name: :func:`create` and :func:`create_local`."""

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
