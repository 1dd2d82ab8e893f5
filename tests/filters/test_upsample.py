"""Joint bilateral upsampling: gradients, known answers and the banded no-gradient path."""

import math

import pytest
import torch
import torch.nn.functional as F
from torch.autograd import gradcheck

from wise.errors import WiseError
from wise.filters import upsample as U
from wise.filters.upsample import downsample, joint_bilateral_upsample

DOUBLE = torch.float64


def _rand(*shape: int, low: float = 0.0, high: float = 1.0, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return torch.rand(*shape, generator=g, dtype=DOUBLE) * (high - low) + low


def _reference(low, guide, sigma_spatial: float, sigma_range: float, radius: int) -> torch.Tensor:
    """Kopf et al.'s sum written out pixel by pixel."""
    b, c, h, w = low.shape
    height, width = guide.shape[-2:]
    guide_low = F.adaptive_avg_pool2d(guide, (h, w))
    out = torch.zeros(b, c, height, width, dtype=low.dtype)
    for y in range(height):
        for x in range(width):
            uy = (y + 0.5) * h / height - 0.5
            ux = (x + 0.5) * w / width - 0.5
            total = torch.zeros(b, c, dtype=low.dtype)
            norm = torch.zeros(b, 1, dtype=low.dtype)
            for qy in range(math.floor(uy) + 1 - radius, math.floor(uy) + radius + 1):
                for qx in range(math.floor(ux) + 1 - radius, math.floor(ux) + radius + 1):
                    cy, cx = min(max(qy, 0), h - 1), min(max(qx, 0), w - 1)
                    spatial = ((qy - uy) ** 2 + (qx - ux) ** 2) / (2 * sigma_spatial**2)
                    colour = ((guide[:, :, y, x] - guide_low[:, :, cy, cx]) ** 2).sum(1, keepdim=True)
                    weight = torch.exp(-spatial - colour / (2 * sigma_range**2))
                    total += weight * low[:, :, cy, cx]
                    norm += weight
            out[:, :, y, x] = total / norm
    return out


@pytest.mark.parametrize("maps", [False, True])
def test_gradcheck(maps: bool) -> None:
    low = _rand(2, 1, 3, 4).requires_grad_()
    guide = _rand(2, 2, 5, 6, seed=1).requires_grad_()
    if maps:
        sigma_spatial = _rand(2, 1, 5, 6, low=0.8, high=1.2, seed=2).requires_grad_()
        sigma_range = _rand(2, low=0.4, high=0.8, seed=3).requires_grad_()
    else:
        sigma_spatial = _rand(2, low=0.8, high=1.2, seed=2).requires_grad_()
        sigma_range = _rand(2, 1, 5, 6, low=0.4, high=0.8, seed=3).requires_grad_()
    inputs = (low, guide, sigma_spatial, sigma_range)
    # radius 1 keeps the check fast; every tap runs the same code
    upsample = lambda *a: joint_bilateral_upsample(*a, radius=1)  # noqa: E731
    assert gradcheck(upsample, inputs, eps=1e-6, nondet_tol=1e-12, atol=1e-5, rtol=1e-3)


def test_downsample_gradcheck() -> None:
    image = _rand(1, 1, 5, 7).requires_grad_()
    assert gradcheck(lambda i: downsample(i, 2.5), (image,), eps=1e-6, nondet_tol=1e-12, atol=1e-5, rtol=1e-3)


@pytest.mark.parametrize("radius", [1, 2])
def test_matches_the_written_out_sum(radius: int) -> None:
    low = _rand(1, 2, 4, 5)
    guide = _rand(1, 3, 9, 11, seed=1)
    expected = _reference(low, guide, 0.9, 0.3, radius)
    result = joint_bilateral_upsample(low, guide, 0.9, 0.3, radius)
    assert torch.allclose(result, expected, atol=1e-12)


def test_huge_range_sigma_is_gaussian_upsampling() -> None:
    low = _rand(1, 2, 4, 5)
    guide = _rand(1, 3, 10, 13, seed=1)
    result = joint_bilateral_upsample(low, guide, 1.1, 1e6)
    gaussian = _reference(low, torch.zeros_like(guide), 1.1, 1.0, 2)
    assert torch.allclose(result, gaussian, atol=1e-9)


def test_constant_stays_constant() -> None:
    low = torch.full((2, 3, 5, 6), 0.37)
    guide = torch.rand(2, 3, 17, 23)
    assert torch.allclose(joint_bilateral_upsample(low, guide, 1.0, 0.05), low.new_full((2, 3, 17, 23), 0.37))


def test_edge_between_low_pixels_comes_back_sharp() -> None:
    size, factor = 64, 4
    columns = torch.arange(size)
    truth = (columns >= 30).float().view(1, 1, 1, size).expand(1, 1, size, size)
    guide = torch.cat((truth, 1.0 - truth, 0.5 * truth), dim=1)
    low = downsample(truth, factor)  # the low-resolution pixel over columns 28..31 is a mix
    assert 0.4 < float(low[0, 0, 0, 7]) < 0.6
    upsampled = joint_bilateral_upsample(low, guide, 1.0, 0.1)
    bilinear = F.interpolate(low, size=(size, size), mode="bilinear", align_corners=False)
    assert (upsampled - truth).abs().max() < 0.02
    assert (bilinear - truth).abs().max() > 0.3
    assert (upsampled - truth).abs().mean() < 0.1 * (bilinear - truth).abs().mean()


def test_pixel_unlike_every_neighbour_falls_back_to_spatial_weights() -> None:
    low = torch.rand(1, 1, 4, 4)
    guide = torch.zeros(1, 1, 16, 16)
    guide[..., 7, 9] = 100.0
    result = joint_bilateral_upsample(low, guide, 1.0, 0.01)
    spatial_only = joint_bilateral_upsample(low, torch.zeros_like(guide), 1.0, 0.01)
    assert torch.isfinite(result).all()
    assert torch.allclose(result[..., 7, 9], spatial_only[..., 7, 9], atol=1e-5)


def test_banded_path_matches_autograd_path(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(U, "BAND_PIXELS", 40)  # bands of two output rows
    low = torch.rand(2, 3, 6, 7)
    guide = torch.rand(2, 3, 15, 20)
    sigma_spatial = torch.rand(2, 1, 15, 20) + 0.5
    sigma_range = torch.rand(2) * 0.2 + 0.1
    with torch.no_grad():
        banded = joint_bilateral_upsample(low, guide, sigma_spatial, sigma_range)
    whole = joint_bilateral_upsample(low.requires_grad_(), guide, sigma_spatial, sigma_range)
    assert torch.allclose(banded, whole.detach(), atol=1e-6)


def test_gradients_reach_every_input() -> None:
    low = torch.rand(1, 3, 8, 8, requires_grad=True)
    guide = torch.rand(1, 3, 24, 24, requires_grad=True)
    sigma_spatial = torch.full((1,), 1.0, requires_grad=True)
    sigma_range = torch.full((1, 1, 24, 24), 0.2, requires_grad=True)
    (joint_bilateral_upsample(low, guide, sigma_spatial, sigma_range) * torch.rand(1, 3, 24, 24)).sum().backward()
    for tensor in (low, guide, sigma_spatial, sigma_range):
        assert tensor.grad is not None and tensor.grad.abs().sum() > 0


def test_downsample_averages_areas() -> None:
    image = torch.arange(16.0).view(1, 1, 4, 4)
    assert torch.equal(downsample(image, 2.0), torch.tensor([[[[2.5, 4.5], [10.5, 12.5]]]]))
    assert downsample(torch.rand(1, 2, 100, 60), 3.3).shape == (1, 2, 30, 18)


def test_bad_input_raises() -> None:
    with pytest.raises(WiseError):
        joint_bilateral_upsample(torch.rand(1, 3, 8, 8), torch.rand(1, 3, 6, 16))
    with pytest.raises(WiseError):
        joint_bilateral_upsample(torch.rand(2, 3, 4, 4), torch.rand(1, 3, 8, 8))
    with pytest.raises(WiseError):
        joint_bilateral_upsample(torch.rand(1, 3, 4, 4), torch.rand(1, 3, 8, 8), radius=0)
    with pytest.raises(WiseError):
        downsample(torch.rand(1, 3, 8, 8), 0.5)
