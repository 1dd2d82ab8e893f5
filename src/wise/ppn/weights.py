"""ImageNet backbone weights from safetensors files in torchvision's state-dict layout.

Weights are never downloaded: the user passes a file (e.g. torchvision's ``resnet50`` or
``vgg11`` state dict saved with ``safetensors.torch.save_file``). Pickled files are refused.
Every name and shape is checked before anything is copied into the model.
"""

from __future__ import annotations

import os

import torch
from torch import nn

from wise.errors import WiseError
from wise.files import MAX_MODEL_BYTES, read_safetensors, safetensors_path
from wise.ppn.multifeature import MultiFeaturePPN
from wise.ppn.resnet import ResNetPPN

BATCHNORM_EPS = 1e-5
"""torchvision's BatchNorm epsilon."""


def _tensors(path: str | os.PathLike[str], what: str) -> dict[str, torch.Tensor]:
    tensors, _ = read_safetensors(safetensors_path(path, what), what, MAX_MODEL_BYTES)
    return tensors


def _take(tensors: dict[str, torch.Tensor], key: str, shape: tuple[int, ...], path: object) -> torch.Tensor:
    if key not in tensors:
        raise WiseError(f"{path}: {key} is missing; pass torchvision's state dict of the backbone")
    value = tensors[key]
    if tuple(value.shape) != shape:
        raise WiseError(f"{path}: {key} has the shape {tuple(value.shape)}, expected {shape}")
    return value.to(torch.float32)


def _widen_input(weight: torch.Tensor, channels: int) -> torch.Tensor:
    """RGB filters for ``channels`` inputs (photo and example): repeated, scaled to keep the response."""
    repeats = channels // weight.shape[1]
    return weight.repeat(1, repeats, 1, 1) / repeats


def fold_batchnorm(conv: nn.Conv2d, weight: torch.Tensor, bn: dict[str, torch.Tensor]) -> None:
    """Set ``conv`` to ``BatchNorm(conv_weight(x))`` in evaluation mode, as one convolution with a bias."""
    scale = bn["weight"] / torch.sqrt(bn["running_var"] + BATCHNORM_EPS)
    with torch.no_grad():
        conv.weight.copy_(weight * scale.view(-1, 1, 1, 1))
        conv.bias.copy_(bn["bias"] - bn["running_mean"] * scale)


def load_resnet50(model: ResNetPPN, path: str | os.PathLike[str]) -> ResNetPPN:
    """ImageNet weights of torchvision's ``resnet50`` into ``model``'s backbone (BatchNorm folded)."""
    tensors = _tensors(path, "ResNet-50 weights")
    for name, module in model.named_modules():
        if not isinstance(module, nn.Conv2d) or name.startswith("heads"):
            continue
        bn_name = name.replace("downsample", "downsample.1") if "downsample" in name else name.replace("conv", "bn")
        conv_key = f"{name.replace('downsample', 'downsample.0')}.weight"
        in_channels = 3 if name == "conv1" else module.in_channels
        shape = (module.out_channels, in_channels, *module.kernel_size)
        weight = _take(tensors, conv_key, shape, path)
        if name == "conv1":
            weight = _widen_input(weight, module.in_channels)
        channels = (module.out_channels,)
        bn = {
            part: _take(tensors, f"{bn_name}.{part}", channels, path)
            for part in ("weight", "bias", "running_mean", "running_var")
        }
        fold_batchnorm(module, weight, bn)
    return model


def load_vgg11(model: MultiFeaturePPN, path: str | os.PathLike[str]) -> MultiFeaturePPN:
    """ImageNet weights of torchvision's ``vgg11`` (``features.<i>``) into ``model``'s backbone."""
    tensors = _tensors(path, "VGG-11 weights")
    state = {}
    for name, value in model.features.state_dict().items():
        state[name] = _take(tensors, f"features.{name}", tuple(value.shape), path)
    model.features.load_state_dict(state)
    return model
