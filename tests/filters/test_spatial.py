"""Behaviour of the spatial filters on images whose answer is known."""

import math

import pytest
import torch

from wise import filters as W
from wise.filters.sampling import tap_sum


def _stripes(size: int = 64, vertical: bool = True) -> torch.Tensor:
    coords = torch.arange(size, dtype=torch.float32)
    wave = (torch.sin(coords / 3.0) > 0).float()
    image = (
        wave.view(1, 1, 1, size).expand(1, 1, size, size)
        if vertical
        else wave.view(1, 1, size, 1).expand(1, 1, size, size)
    )
    return image.contiguous()


def _field(x: float, y: float, size: int = 64) -> torch.Tensor:
    return torch.tensor([x, y]).view(1, 2, 1, 1).expand(1, 2, size, size).contiguous()


def test_gaussian_preserves_constants_and_matches_map_path() -> None:
    constant = torch.full((1, 2, 20, 20), 0.3)
    assert torch.allclose(W.gaussian_blur(constant, 2.0, scale=1.0), constant)
    image = torch.rand(1, 2, 20, 24)
    by_float = W.gaussian_blur(image, 1.7, scale=1.0)
    by_map = W.gaussian_blur(image, torch.full((1, 1, 20, 24), 1.7), scale=1.0)
    assert torch.allclose(by_float, by_map, atol=1e-5)


def test_gaussian_scales_with_resolution() -> None:
    def spread(size: int) -> float:
        impulse = torch.zeros(1, 1, size, size)
        impulse[..., size // 2, size // 2] = 1.0
        row = W.gaussian_blur(impulse, 3.0)[0, 0, size // 2]
        x = torch.arange(size, dtype=torch.float32) - size // 2
        return float(((row / row.sum()) * x * x).sum().sqrt())

    assert spread(1024) / spread(512) == pytest.approx(2.0, rel=0.05)


def test_edge_tangent_flow_follows_edges() -> None:
    for vertical, expected in ((True, (0.0, 1.0)), (False, (1.0, 0.0))):
        tensor = W.smoothed_structure_tensor(_stripes(vertical=vertical), 1.0, 2.0, scale=1.0)
        tangent = W.edge_tangent_flow(tensor)[..., 8:-8, 8:-8]
        alignment = (tangent[:, 0] * expected[0] + tangent[:, 1] * expected[1]).abs()
        assert alignment.min() > 0.99


def test_edge_tangent_flow_on_a_circle() -> None:
    size = 65
    ys, xs = torch.meshgrid(torch.arange(size) - 32.0, torch.arange(size) - 32.0, indexing="ij")
    disk = ((xs**2 + ys**2).sqrt() < 20).float().view(1, 1, size, size)
    tangent = W.edge_tangent_flow(W.smoothed_structure_tensor(disk, 1.0, 1.5, scale=1.0))
    on_rim = ((xs**2 + ys**2).sqrt() - 20).abs() < 1.0
    radial = torch.stack((xs, ys)) / (xs**2 + ys**2).sqrt().clamp_min(1e-6)
    cosine = (tangent[0] * radial).sum(0).abs()[on_rim]
    assert cosine.max() < 0.2


def test_bilateral_keeps_edges_and_removes_noise() -> None:
    torch.manual_seed(0)
    step = torch.zeros(1, 3, 48, 48)
    step[..., 24:, :] = 50.0
    noisy = step + torch.randn_like(step)
    tangent = _field(1.0, 0.0, 48)  # edges run horizontally
    across = W.bilateral_pass(noisy, W.gradient_direction(tangent), 4.0, 5.0, 3, 1.0)
    assert (across - step)[..., 4:-4, :].std() < 0.7 * (noisy - step)[..., 4:-4, :].std()
    assert (across[..., 26:, :].mean() - across[..., :22, :].mean()) > 49.0


def test_bilateral_direction_matters() -> None:
    image = _stripes(vertical=True).expand(1, 3, 64, 64).contiguous()
    along = W.bilateral_pass(image, _field(0.0, 1.0), 3.0, 100.0, 3, 1.0)
    across = W.bilateral_pass(image, _field(1.0, 0.0), 3.0, 100.0, 3, 1.0)
    assert torch.allclose(along, image, atol=1e-5)
    assert (across - image).abs().mean() > 0.05


def test_flow_dog_and_smoothing_keep_constants() -> None:
    constant = torch.full((1, 1, 32, 32), 0.4)
    tangent = W.edge_tangent_flow(W.smoothed_structure_tensor(torch.rand(1, 1, 32, 32), 1.0, 2.0, scale=1.0))
    assert torch.allclose(W.flow_dog(constant, tangent, 1.0, 20.0, 10, 1.0), constant, atol=1e-5)
    assert torch.allclose(W.flow_smoothing(constant, tangent, 3.0, scale=1.0), constant, atol=1e-6)


def test_flow_smoothing_smooths_only_along_the_flow() -> None:
    torch.manual_seed(0)
    noise = torch.rand(1, 1, 64, 64)
    smoothed = W.flow_smoothing(noise, _field(1.0, 0.0), 4.0, scale=1.0)
    row_variation = (smoothed[..., 1:] - smoothed[..., :-1]).abs().mean()
    column_variation = (smoothed[..., 1:, :] - smoothed[..., :-1, :]).abs().mean()
    assert row_variation < 0.35 * column_variation


def test_flow_dog_responds_across_edges_only() -> None:
    image = _stripes(vertical=True)
    tangent_along_stripes = _field(0.0, 1.0)
    response = W.flow_dog(image, tangent_along_stripes, 1.0, 20.0, 10, 1.0)
    assert (response - image).abs().max() > 1.0
    response_along = W.flow_dog(image, _field(1.0, 0.0), 1.0, 20.0, 10, 1.0)
    assert torch.allclose(response_along, image, atol=1e-5)


def test_xdog_threshold_values() -> None:
    u = torch.tensor([0.0, 0.19, 0.2, 0.9]).view(1, 1, 1, 4)
    out = W.xdog_threshold(u, 0.2, 10.0)
    expected = torch.tensor([1 + math.tanh(-2.0), 1 + math.tanh(-0.1), 1.0, 1.0])
    assert torch.allclose(out.flatten(), expected, atol=1e-6)


def test_tap_sum_keeps_only_its_inputs_for_backward() -> None:
    """The structure-adaptive filters must not store per-sample tensors for backward."""
    image = torch.rand(1, 3, 64, 64, requires_grad=True)
    tangent = _field(0.6, 0.8)
    saved: list[int] = []

    def pack(t: torch.Tensor) -> torch.Tensor:
        saved.append(t.numel())
        return t

    with torch.autograd.graph.saved_tensors_hooks(pack, lambda t: t):
        out = W.bilateral_pass(image, tangent, 6.0, 10.0, 3, 1.0)
        W.flow_dog(out[:, :1], tangent, 2.0, 10.0, 10, 1.0)
    image_size = image.numel()
    # a copy per sample (12 bilateral + 20 DoG samples) would be >= 32 image sizes
    assert sum(saved) < 12 * image_size


def test_tap_sum_matches_plain_autograd() -> None:
    image = torch.rand(1, 2, 9, 9, dtype=torch.float64, requires_grad=True)
    weights = torch.rand(5, dtype=torch.float64, requires_grad=True)

    def tap(k, image, weights):
        return (weights[k] * image.roll(k, dims=-1), weights[k].expand(1, 1, 9, 9))

    total, norm = tap_sum(tap, 5, image, weights)
    (total.sum() + 2 * norm.sum()).backward()
    g_image, g_weights = image.grad.clone(), weights.grad.clone()
    image.grad = weights.grad = None
    plain_total = sum(weights[k] * image.roll(k, dims=-1) for k in range(5))
    plain_norm = sum(weights[k].expand(1, 1, 9, 9) for k in range(5))
    (plain_total.sum() + 2 * plain_norm.sum()).backward()
    assert torch.allclose(g_image, image.grad) and torch.allclose(g_weights, weights.grad)
