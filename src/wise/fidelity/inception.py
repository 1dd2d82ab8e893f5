"""The Inception-v3 network of FID (Heusel et al. 2017, "GANs Trained by a Two Time-Scale Update Rule
Converge to a Local Nash Equilibrium"), as pytorch-fid and torch-fidelity run it.

The weights are TensorFlow's Inception of 2015-12-05 ported to PyTorch by pytorch-fid: the release file
``pt_inception-2015-12-05-6726825d.pth`` of https://github.com/mseitzer/pytorch-fid (1008 logits). They
are never downloaded and pickles are never loaded: convert that file on your own machine with
``safetensors.torch.save_file(torch.load("pt_inception-2015-12-05-6726825d.pth"), "x.safetensors")``
and pass the result, or place it at ``~/.cache/wise/pt_inception-2015-12-05.safetensors``
(``$XDG_CACHE_HOME/wise/...`` when that is set). The keys are torchvision's ``inception_v3`` names
without ``AuxLogits`` (``Conv2d_1a_3x3.conv.weight``, ``Mixed_5b.branch1x1.bn.running_var``, ...,
``fc.bias``); ``num_batches_tracked`` entries may be present or not.

The FID variant differs from torchvision's network in its pooling branches: the average pools of
``Mixed_5b``-``Mixed_7b`` leave the zero padding out of the mean (as TensorFlow does) and ``Mixed_7c``
pools by maximum."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from wise.errors import WiseError
from wise.pretrained import PathLike, WeightsKind, cache_file, read_weights, weights_file

DEFAULT_WEIGHTS = cache_file("pt_inception-2015-12-05.safetensors")
INPUT_SIZE = 299
"""Images are resized bilinearly to 299x299, the input size of Inception-v3."""
FEATURES = 2048
"""Length of the pool features that FID compares."""
CLASSES = 1008
"""Logits of the TensorFlow Inception of 2015-12-05 (1000 ImageNet classes and 8 unused)."""
BN_EPS = 1e-3
"""Batch normalization epsilon of TensorFlow's Inception."""
POOL_KERNEL = 3
DOWNSAMPLE_STRIDE = 2
SAME_PADDING = 1
"""Padding that keeps the size under a 3x3 pool of stride 1."""


INCEPTION = WeightsKind(
    what="Inception weights",
    origin="the Inception weights of pytorch-fid (pt_inception-2015-12-05)",
    user="FID",
    option="--inception-weights",
    network="a state dict of the FID Inception network",
)


def check_images(images: torch.Tensor, what: str = "images") -> None:
    """Refuse anything but a floating-point ``(B, 3, H, W)`` tensor with at least one image."""
    if not isinstance(images, torch.Tensor):
        raise WiseError(f"{what} must be a torch tensor of shape (B, 3, H, W), not {type(images).__name__}")
    if images.dim() != 4 or images.shape[1] != 3 or images.shape[0] == 0:
        raise WiseError(f"{what} have the shape {list(images.shape)}; pass RGB images as a (B, 3, H, W) tensor")
    if not images.is_floating_point():
        raise WiseError(f"{what} are {images.dtype}; pass floating-point images in [0, 1]")


class _FrozenBatchNorm(nn.Module):
    """Batch normalization with fixed statistics (evaluation only), so no ``num_batches_tracked``."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.weight = nn.Parameter(torch.ones(channels))
        self.bias = nn.Parameter(torch.zeros(channels))
        self.register_buffer("running_mean", torch.zeros(channels))
        self.register_buffer("running_var", torch.ones(channels))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.batch_norm(x, self.running_mean, self.running_var, self.weight, self.bias, False, 0.0, BN_EPS)


class _ConvBN(nn.Module):
    """Convolution without bias, batch normalization and ReLU (torchvision's ``BasicConv2d``)."""

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        kernel: int | tuple[int, int],
        stride: int = 1,
        padding: int | tuple[int, int] = 0,
    ) -> None:
        super().__init__()
        self.conv = nn.Conv2d(in_channels, out_channels, kernel, stride=stride, padding=padding, bias=False)
        self.bn = _FrozenBatchNorm(out_channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(self.bn(self.conv(x)))


def _chain(x: torch.Tensor, *layers: nn.Module) -> torch.Tensor:
    for layer in layers:
        x = layer(x)
    return x


def _average_pool(x: torch.Tensor) -> torch.Tensor:
    """3x3 average of stride 1 over the pixels inside the image (TensorFlow leaves the padding out)."""
    return F.avg_pool2d(x, POOL_KERNEL, stride=1, padding=SAME_PADDING, count_include_pad=False)


def _max_pool_same(x: torch.Tensor) -> torch.Tensor:
    return F.max_pool2d(x, POOL_KERNEL, stride=1, padding=SAME_PADDING)


def _downsample(x: torch.Tensor) -> torch.Tensor:
    return F.max_pool2d(x, POOL_KERNEL, stride=DOWNSAMPLE_STRIDE)


class _BlockA(nn.Module):
    """``Mixed_5b``-``Mixed_5d``: 1x1, 5x5 and double 3x3 branches and an average-pool branch."""

    def __init__(self, in_channels: int, pool_channels: int) -> None:
        super().__init__()
        self.branch1x1 = _ConvBN(in_channels, 64, 1)
        self.branch5x5_1 = _ConvBN(in_channels, 48, 1)
        self.branch5x5_2 = _ConvBN(48, 64, 5, padding=2)
        self.branch3x3dbl_1 = _ConvBN(in_channels, 64, 1)
        self.branch3x3dbl_2 = _ConvBN(64, 96, 3, padding=1)
        self.branch3x3dbl_3 = _ConvBN(96, 96, 3, padding=1)
        self.branch_pool = _ConvBN(in_channels, pool_channels, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        branches = (
            self.branch1x1(x),
            _chain(x, self.branch5x5_1, self.branch5x5_2),
            _chain(x, self.branch3x3dbl_1, self.branch3x3dbl_2, self.branch3x3dbl_3),
            self.branch_pool(_average_pool(x)),
        )
        return torch.cat(branches, 1)


class _BlockB(nn.Module):
    """``Mixed_6a``: halves the size with a strided 3x3, a strided double 3x3 and a max pool."""

    def __init__(self, in_channels: int) -> None:
        super().__init__()
        self.branch3x3 = _ConvBN(in_channels, 384, 3, stride=DOWNSAMPLE_STRIDE)
        self.branch3x3dbl_1 = _ConvBN(in_channels, 64, 1)
        self.branch3x3dbl_2 = _ConvBN(64, 96, 3, padding=1)
        self.branch3x3dbl_3 = _ConvBN(96, 96, 3, stride=DOWNSAMPLE_STRIDE)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        double = _chain(x, self.branch3x3dbl_1, self.branch3x3dbl_2, self.branch3x3dbl_3)
        return torch.cat((self.branch3x3(x), double, _downsample(x)), 1)


class _BlockC(nn.Module):
    """``Mixed_6b``-``Mixed_6e``: factorized 7x7 branches (1x7 and 7x1) and an average-pool branch."""

    def __init__(self, in_channels: int, mid: int) -> None:
        super().__init__()
        self.branch1x1 = _ConvBN(in_channels, 192, 1)
        self.branch7x7_1 = _ConvBN(in_channels, mid, 1)
        self.branch7x7_2 = _ConvBN(mid, mid, (1, 7), padding=(0, 3))
        self.branch7x7_3 = _ConvBN(mid, 192, (7, 1), padding=(3, 0))
        self.branch7x7dbl_1 = _ConvBN(in_channels, mid, 1)
        self.branch7x7dbl_2 = _ConvBN(mid, mid, (7, 1), padding=(3, 0))
        self.branch7x7dbl_3 = _ConvBN(mid, mid, (1, 7), padding=(0, 3))
        self.branch7x7dbl_4 = _ConvBN(mid, mid, (7, 1), padding=(3, 0))
        self.branch7x7dbl_5 = _ConvBN(mid, 192, (1, 7), padding=(0, 3))
        self.branch_pool = _ConvBN(in_channels, 192, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        double = (self.branch7x7dbl_1, self.branch7x7dbl_2, self.branch7x7dbl_3, self.branch7x7dbl_4)
        branches = (
            self.branch1x1(x),
            _chain(x, self.branch7x7_1, self.branch7x7_2, self.branch7x7_3),
            _chain(x, *double, self.branch7x7dbl_5),
            self.branch_pool(_average_pool(x)),
        )
        return torch.cat(branches, 1)


class _BlockD(nn.Module):
    """``Mixed_7a``: halves the size with a strided 3x3, a 7x7-then-strided-3x3 branch and a max pool."""

    def __init__(self, in_channels: int) -> None:
        super().__init__()
        self.branch3x3_1 = _ConvBN(in_channels, 192, 1)
        self.branch3x3_2 = _ConvBN(192, 320, 3, stride=DOWNSAMPLE_STRIDE)
        self.branch7x7x3_1 = _ConvBN(in_channels, 192, 1)
        self.branch7x7x3_2 = _ConvBN(192, 192, (1, 7), padding=(0, 3))
        self.branch7x7x3_3 = _ConvBN(192, 192, (7, 1), padding=(3, 0))
        self.branch7x7x3_4 = _ConvBN(192, 192, 3, stride=DOWNSAMPLE_STRIDE)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        short = _chain(x, self.branch3x3_1, self.branch3x3_2)
        long = _chain(x, self.branch7x7x3_1, self.branch7x7x3_2, self.branch7x7x3_3, self.branch7x7x3_4)
        return torch.cat((short, long, _downsample(x)), 1)


class _BlockE(nn.Module):
    """``Mixed_7b`` (average pool) and ``Mixed_7c`` (max pool): 3x3 branches split into 1x3 and 3x1."""

    def __init__(self, in_channels: int, max_pool: bool) -> None:
        super().__init__()
        self.pool = _max_pool_same if max_pool else _average_pool
        self.branch1x1 = _ConvBN(in_channels, 320, 1)
        self.branch3x3_1 = _ConvBN(in_channels, 384, 1)
        self.branch3x3_2a = _ConvBN(384, 384, (1, 3), padding=(0, 1))
        self.branch3x3_2b = _ConvBN(384, 384, (3, 1), padding=(1, 0))
        self.branch3x3dbl_1 = _ConvBN(in_channels, 448, 1)
        self.branch3x3dbl_2 = _ConvBN(448, 384, 3, padding=1)
        self.branch3x3dbl_3a = _ConvBN(384, 384, (1, 3), padding=(0, 1))
        self.branch3x3dbl_3b = _ConvBN(384, 384, (3, 1), padding=(1, 0))
        self.branch_pool = _ConvBN(in_channels, 192, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        single = self.branch3x3_1(x)
        double = _chain(x, self.branch3x3dbl_1, self.branch3x3dbl_2)
        branches = (
            self.branch1x1(x),
            self.branch3x3_2a(single),
            self.branch3x3_2b(single),
            self.branch3x3dbl_3a(double),
            self.branch3x3dbl_3b(double),
            self.branch_pool(self.pool(x)),
        )
        return torch.cat(branches, 1)


class FIDInception(nn.Module):
    """Inception-v3 of pytorch-fid: ``forward`` maps images to their 2048 pool features.

    The state dict has exactly the keys of ``pt_inception-2015-12-05`` (see :func:`expected_shapes`).
    """

    def __init__(self) -> None:
        super().__init__()
        self.Conv2d_1a_3x3 = _ConvBN(3, 32, 3, stride=DOWNSAMPLE_STRIDE)
        self.Conv2d_2a_3x3 = _ConvBN(32, 32, 3)
        self.Conv2d_2b_3x3 = _ConvBN(32, 64, 3, padding=1)
        self.Conv2d_3b_1x1 = _ConvBN(64, 80, 1)
        self.Conv2d_4a_3x3 = _ConvBN(80, 192, 3)
        self.Mixed_5b = _BlockA(192, pool_channels=32)
        self.Mixed_5c = _BlockA(256, pool_channels=64)
        self.Mixed_5d = _BlockA(288, pool_channels=64)
        self.Mixed_6a = _BlockB(288)
        self.Mixed_6b = _BlockC(768, mid=128)
        self.Mixed_6c = _BlockC(768, mid=160)
        self.Mixed_6d = _BlockC(768, mid=160)
        self.Mixed_6e = _BlockC(768, mid=192)
        self.Mixed_7a = _BlockD(768)
        self.Mixed_7b = _BlockE(1280, max_pool=False)
        self.Mixed_7c = _BlockE(FEATURES, max_pool=True)
        self.fc = nn.Linear(FEATURES, CLASSES)  # unused by FID, but part of the weight file

    def _stem(self, x: torch.Tensor) -> torch.Tensor:
        x = _chain(x, self.Conv2d_1a_3x3, self.Conv2d_2a_3x3, self.Conv2d_2b_3x3)
        return _downsample(_chain(_downsample(x), self.Conv2d_3b_1x1, self.Conv2d_4a_3x3))

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """Pool features ``(B, 2048)`` (float32) of ``images`` ``(B, 3, H, W)`` in [0, 1] of any size."""
        check_images(images)
        x = images.to(self.fc.weight.device, torch.float32)
        x = F.interpolate(x, size=(INPUT_SIZE, INPUT_SIZE), mode="bilinear", align_corners=False)
        x = self._stem(2 * x - 1)
        blocks = (self.Mixed_5b, self.Mixed_5c, self.Mixed_5d, self.Mixed_6a, self.Mixed_6b, self.Mixed_6c)
        x = _chain(x, *blocks, self.Mixed_6d, self.Mixed_6e, self.Mixed_7a, self.Mixed_7b, self.Mixed_7c)
        return x.mean(dim=(2, 3))


def expected_shapes() -> dict[str, tuple[int, ...]]:
    """The shape of every tensor of ``pt_inception-2015-12-05``, by key (472 tensors)."""
    with torch.device("meta"):
        model = FIDInception()
    return {key: tuple(value.shape) for key, value in model.state_dict().items()}


def load_inception(path: PathLike | None = None) -> FIDInception:
    """The FID Inception network with weights from ``path`` or :data:`DEFAULT_WEIGHTS`, in evaluation mode.

    Only the keys of :func:`expected_shapes` are read; ``num_batches_tracked`` and other extra keys are ignored.
    """
    file = weights_file(path, DEFAULT_WEIGHTS, INCEPTION)
    state = read_weights(file, expected_shapes(), INCEPTION)
    model = FIDInception()
    model.load_state_dict(state)
    return model.eval().requires_grad_(False)
