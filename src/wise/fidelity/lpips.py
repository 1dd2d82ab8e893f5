"""LPIPS (Zhang et al. 2018, "The Unreasonable Effectiveness of Deep Features as a Perceptual Metric"),
the AlexNet variant of version 0.1 of the ``lpips`` package.

Two weight files are needed, never downloaded and never loaded from pickles:

- the AlexNet backbone: torchvision's ``alexnet`` ImageNet weights (``alexnet-owt-7be5be79.pth``), of which
  the keys ``features.0``, ``.3``, ``.6``, ``.8`` and ``.10`` (``.weight`` and ``.bias``) are read; default
  ``~/.cache/wise/alexnet.safetensors``;
- the learned linear layers: ``lpips/weights/v0.1/alex.pth`` of https://github.com/richzhang/PerceptualSimilarity
  (keys ``lin0.model.1.weight`` ... ``lin4.model.1.weight``); default ``~/.cache/wise/lpips-alex.safetensors``.

One file holding both key sets is accepted as well. Convert a ``.pth`` file on your own machine with
``safetensors.torch.save_file(torch.load("alex.pth"), "lpips-alex.safetensors")``. The cache folder is
``$XDG_CACHE_HOME/wise`` when that is set.
"""

from __future__ import annotations

from pathlib import Path

import torch
from torch import nn

from wise.errors import WiseError, size_text
from wise.fidelity.inception import check_images
from wise.files import MAX_MODEL_BYTES, read_safetensors_header
from wise.pretrained import PathLike, WeightsKind, cache_file, check_header, read_weights, weights_file

DEFAULT_ALEXNET_WEIGHTS = cache_file("alexnet.safetensors")
DEFAULT_LINEAR_WEIGHTS = cache_file("lpips-alex.safetensors")
ALEXNET_CONVS = (
    # (index in torchvision's ``features``, out channels, in channels, kernel, stride, padding)
    (0, 64, 3, 11, 4, 2),
    (3, 192, 64, 5, 1, 2),
    (6, 384, 192, 3, 1, 1),
    (8, 256, 384, 3, 1, 1),
    (10, 256, 256, 3, 1, 1),
)
POOLED = (0, 3)
"""Convolutions whose ReLU is followed by a 3x3 max pool of stride 2."""
POOL_KERNEL, POOL_STRIDE = 3, 2
SHIFT = (-0.030, -0.088, -0.188)
SCALE = (0.458, 0.448, 0.450)
"""LPIPS's scaling layer: ``(x - SHIFT) / SCALE`` for images ``x`` in [-1, 1]."""
NORM_EPS = 1e-10
"""Added to the channel norm before dividing by it, as LPIPS does."""
MIN_SIZE = 31
"""Smallest height and width that AlexNet's stride-4 convolution and two 3x3 pools leave at least a pixel of."""

ALEXNET = WeightsKind(
    what="AlexNet weights",
    origin="the AlexNet weights of torchvision (alexnet-owt-7be5be79)",
    user="LPIPS",
    option="--alexnet-weights",
    network="a state dict of torchvision's AlexNet",
)
LINEAR = WeightsKind(
    what="LPIPS weights",
    origin="the linear layers of LPIPS v0.1 for AlexNet (lpips/weights/v0.1/alex.pth)",
    user="LPIPS",
    option="--lpips-weights",
    network="the linear layers of LPIPS v0.1 for AlexNet",
)


def alexnet_shapes() -> dict[str, tuple[int, ...]]:
    """The shape of every AlexNet ``features.<i>.weight`` / ``.bias`` tensor, by key."""
    shapes: dict[str, tuple[int, ...]] = {}
    for index, out_channels, in_channels, kernel, _, _ in ALEXNET_CONVS:
        shapes[f"features.{index}.weight"] = (out_channels, in_channels, kernel, kernel)
        shapes[f"features.{index}.bias"] = (out_channels,)
    return shapes


def linear_shapes() -> dict[str, tuple[int, ...]]:
    """The shape ``(1, C, 1, 1)`` of every linear layer ``lin<k>.model.1.weight``, by key."""
    return {f"lin{k}.model.1.weight": (1, conv[1], 1, 1) for k, conv in enumerate(ALEXNET_CONVS)}


def expected_shapes() -> dict[str, tuple[int, ...]]:
    """Every tensor LPIPS reads: :func:`alexnet_shapes` and :func:`linear_shapes`."""
    return {**alexnet_shapes(), **linear_shapes()}


def _alexnet_features() -> nn.Sequential:
    """torchvision's AlexNet ``features`` up to the last ReLU, with its layer indices."""
    layers: list[nn.Module] = []
    for index, out_channels, in_channels, kernel, stride, padding in ALEXNET_CONVS:
        if len(layers) != index:
            raise AssertionError(f"AlexNet layer {index} would be at {len(layers)}")
        layers += [nn.Conv2d(in_channels, out_channels, kernel, stride=stride, padding=padding), nn.ReLU()]
        if index in POOLED:
            layers.append(nn.MaxPool2d(POOL_KERNEL, stride=POOL_STRIDE))
    return nn.Sequential(*layers)


class _Linear(nn.Module):
    """A 1x1 convolution to one channel without bias; the index 0 of ``model`` is LPIPS's dropout, inactive
    at evaluation, kept so that the key is ``model.1.weight``."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.model = nn.Sequential(nn.Identity(), nn.Conv2d(channels, 1, 1, bias=False))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.model(x)


def _unit(features: torch.Tensor) -> torch.Tensor:
    """``(B, C, H, W)`` features divided by their norm over the channels."""
    return features / (features.norm(dim=1, keepdim=True) + NORM_EPS)


class LPIPS(nn.Module):
    """LPIPS v0.1 with AlexNet; the state dict holds exactly the keys of :func:`expected_shapes`."""

    def __init__(self) -> None:
        super().__init__()
        self.features = _alexnet_features()
        for k, conv in enumerate(ALEXNET_CONVS):
            self.add_module(f"lin{k}", _Linear(conv[1]))
        self.register_buffer("shift", torch.tensor(SHIFT).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("scale", torch.tensor(SCALE).view(1, 3, 1, 1), persistent=False)

    def layers(self, images: torch.Tensor) -> list[torch.Tensor]:
        """The five ReLU outputs of AlexNet for ``images`` ``(B, 3, H, W)`` in [0, 1]."""
        x = ((2 * images - 1) - self.shift) / self.scale
        found = []
        for layer in self.features:
            x = layer(x)
            if isinstance(layer, nn.ReLU):
                found.append(x)
        return found

    def forward(self, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        """Distances ``(B,)`` between images ``a`` and ``b``, both ``(B, 3, H, W)`` in [0, 1]."""
        _check_pair(a, b)
        device = self.shift.device
        both = torch.cat((a, b)).to(device, torch.float32)
        count = a.shape[0]
        total = torch.zeros(count, device=device)
        for k, features in enumerate(self.layers(both)):
            unit = _unit(features)
            difference = (unit[:count] - unit[count:]) ** 2
            total = total + self.get_submodule(f"lin{k}")(difference).mean(dim=(1, 2, 3))
        return total


def _check_pair(a: torch.Tensor, b: torch.Tensor) -> None:
    check_images(a, "the first images")
    check_images(b, "the second images")
    if a.shape != b.shape:
        raise WiseError(f"LPIPS compares images of one shape; got {list(a.shape)} and {list(b.shape)}")
    height, width = a.shape[-2:]
    if min(height, width) < MIN_SIZE:
        raise WiseError(
            f"images of {size_text(width, height)} are too small for LPIPS; pass images of at least "
            f"{size_text(MIN_SIZE, MIN_SIZE)}"
        )


def _holds_any(file: Path, keys: dict[str, tuple[int, ...]], kind: WeightsKind) -> bool:
    entries, _ = read_safetensors_header(file, kind.what, MAX_MODEL_BYTES)
    return any(key in entries for key in keys)


def _weight_files(alexnet_weights: PathLike | None, linear_weights: PathLike | None) -> tuple[Path, Path]:
    """(backbone file, linear file); one file given alone serves for both when it holds keys of both."""
    if linear_weights is None:
        backbone = weights_file(alexnet_weights, DEFAULT_ALEXNET_WEIGHTS, ALEXNET)
        if _holds_any(backbone, linear_shapes(), ALEXNET):
            return backbone, backbone
        return backbone, weights_file(None, DEFAULT_LINEAR_WEIGHTS, LINEAR)
    linear = weights_file(linear_weights, DEFAULT_LINEAR_WEIGHTS, LINEAR)
    if alexnet_weights is None and _holds_any(linear, alexnet_shapes(), LINEAR):
        return linear, linear
    return weights_file(alexnet_weights, DEFAULT_ALEXNET_WEIGHTS, ALEXNET), linear


def load_lpips(alexnet_weights: PathLike | None = None, linear_weights: PathLike | None = None) -> LPIPS:
    """LPIPS with the AlexNet and linear weights of these files (or the defaults), in evaluation mode.

    Both headers are checked before any tensor is read. Extra keys (AlexNet's classifier, say) are ignored.
    """
    backbone, linear = _weight_files(alexnet_weights, linear_weights)
    check_header(backbone, alexnet_shapes(), ALEXNET)
    check_header(linear, linear_shapes(), LINEAR)
    state = {**read_weights(backbone, alexnet_shapes(), ALEXNET), **read_weights(linear, linear_shapes(), LINEAR)}
    model = LPIPS()
    model.load_state_dict(state)
    return model.eval().requires_grad_(False)


def lpips(
    a: torch.Tensor,
    b: torch.Tensor,
    model: LPIPS | None = None,
    *,
    alexnet_weights: PathLike | None = None,
    linear_weights: PathLike | None = None,
) -> torch.Tensor:
    """LPIPS distances ``(B,)`` between images ``a`` and ``b`` ``(B, 3, H, W)`` in [0, 1] (0 for identical images).

    ``model`` is a network from :func:`load_lpips`; without it one is loaded from the weight files given
    (or the defaults). Gradients flow to ``a`` and ``b``, so the distance can serve as a loss.
    """
    if model is None:
        model = load_lpips(alexnet_weights, linear_weights)
    return model(a, b)
