"""VGG-19 features (Simonyan & Zisserman 2015) and the neural style loss of Gatys et al. 2016.

Weights are never downloaded: pass a safetensors file holding torchvision's ``vgg19`` state
dict (keys ``features.<i>.weight`` / ``features.<i>.bias``) or place it at
``~/.cache/wise/vgg19.safetensors``. Pickled ``.pth`` files are refused (they can run code).
"""

from __future__ import annotations

import os
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from wise.errors import WiseError
from wise.files import MAX_MODEL_BYTES, read_safetensors, safetensors_path
from wise.pretrained import WeightsKind, check_header

DEFAULT_WEIGHTS = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "wise" / "vgg19.safetensors"
CHANNELS = (
    64,
    64,
    "pool",
    128,
    128,
    "pool",
    256,
    256,
    256,
    256,
    "pool",
    512,
    512,
    512,
    512,
    "pool",
    512,
    512,
    512,
    512,
)
CONTENT_LAYER = "relu4_2"
STYLE_LAYERS = ("relu1_1", "relu2_1", "relu3_1", "relu4_1", "relu5_1")
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)
STYLE_WEIGHT = 1e3
"""Weight of the Gram-matrix style term against the content term."""
WHAT = "VGG-19 weights"
PASS_WEIGHTS = "pass --vgg-weights FILE (a safetensors file of torchvision's vgg19 state dict)"
VGG19 = WeightsKind(
    what=WHAT,
    origin="torchvision's vgg19 state dict",
    user="The neural style loss",
    option="--vgg-weights",
    network="a VGG-19 state dict",
)


def _layer_names() -> list[tuple[int, str]]:
    """(index in torchvision's ``features``, name) of every ReLU."""
    names, block, conv, index = [], 1, 0, 0
    for item in CHANNELS:
        if item == "pool":
            block, conv = block + 1, 0
            index += 1
            continue
        conv += 1
        names.append((index + 1, f"relu{block}_{conv}"))
        index += 2
    return names


class VGG19Features(nn.Module):
    """The convolutional part of VGG-19 up to ``relu5_4``, returning the named ReLU outputs."""

    def __init__(self) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        in_channels = 3
        for item in CHANNELS:
            if item == "pool":
                layers.append(nn.MaxPool2d(2))
            else:
                layers += [nn.Conv2d(in_channels, int(item), 3, padding=1), nn.ReLU()]
                in_channels = int(item)
        self.features = nn.Sequential(*layers)
        self.relu_names = dict(_layer_names())
        self.register_buffer("mean", torch.tensor(IMAGENET_MEAN).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(IMAGENET_STD).view(1, 3, 1, 1), persistent=False)

    def forward(self, image: torch.Tensor, names: tuple[str, ...]) -> dict[str, torch.Tensor]:
        """Features of ``image`` (B, 3, H, W) in [0, 1] at the ReLUs ``names``."""
        x = (image - self.mean) / self.std
        found: dict[str, torch.Tensor] = {}
        for index, layer in enumerate(self.features):
            x = layer(x)
            name = self.relu_names.get(index)
            if name in names:
                found[name] = x
                if len(found) == len(names):
                    break
        return found


def expected_shapes() -> dict[str, tuple[int, ...]]:
    """The shape of every ``features.<i>.weight`` / ``.bias`` tensor of VGG-19, by key."""
    shapes: dict[str, tuple[int, ...]] = {}
    index, in_channels = 0, 3
    for item in CHANNELS:
        if item == "pool":
            index += 1
            continue
        out_channels = int(item)
        shapes[f"features.{index}.weight"] = (out_channels, in_channels, 3, 3)
        shapes[f"features.{index}.bias"] = (out_channels,)
        in_channels, index = out_channels, index + 2
    return shapes


def weights_file(path: str | os.PathLike[str] | None = None) -> Path:
    """The VGG-19 weights file to use, once its header shows every VGG-19 tensor with the right shape.

    Refuses a missing file, a pickled file, anything that is not safetensors and a state dict of another
    network, without reading the tensor data, so that a wrong file fails before any work.
    """
    file = Path(path) if path is not None else DEFAULT_WEIGHTS
    if not os.path.lexists(file):
        raise WiseError(f"VGG-19 weights not found at {file}; {PASS_WEIGHTS} or put that file at {DEFAULT_WEIGHTS}")
    safetensors_path(file, "VGG weights")
    check_header(file, expected_shapes(), VGG19)
    return file


def load_vgg19(path: str | os.PathLike[str] | None = None) -> VGG19Features:
    """VGG-19 features with weights from ``path`` or :data:`DEFAULT_WEIGHTS` (only ``features.*`` is read)."""
    file = weights_file(path)
    state, _ = read_safetensors(file, WHAT, MAX_MODEL_BYTES, keys=expected_shapes())
    model = VGG19Features()
    try:
        model.load_state_dict(state)
    except RuntimeError as error:
        raise WiseError(f"{file}: weights of the wrong shape for VGG-19 ({str(error).splitlines()[0]})") from None
    return model.eval().requires_grad_(False)


def gram(features: torch.Tensor) -> torch.Tensor:
    """Gram matrix of ``(B, C, H, W)`` features, normalized by the number of entries."""
    b, c, h, w = features.shape
    flat = features.reshape(b, c, h * w)
    return flat @ flat.transpose(1, 2) / (c * h * w)


class StyleLoss(nn.Module):
    """Gatys et al. 2016: content features of ``content`` plus Gram matrices of ``style``."""

    def __init__(self, vgg: VGG19Features, content: torch.Tensor, style: torch.Tensor) -> None:
        super().__init__()
        self.vgg = vgg
        with torch.no_grad():
            self.content_features = vgg(content, (CONTENT_LAYER,))[CONTENT_LAYER]
            style_features = vgg(style, STYLE_LAYERS)
            self.style_grams = {name: gram(f) for name, f in style_features.items()}

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        features = self.vgg(image, (CONTENT_LAYER, *STYLE_LAYERS))
        content_term = F.mse_loss(features[CONTENT_LAYER], self.content_features)
        style_term = sum(F.mse_loss(gram(features[n]), self.style_grams[n]) for n in STYLE_LAYERS)
        return content_term + STYLE_WEIGHT * style_term
