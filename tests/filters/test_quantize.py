import pytest
import torch
from torch.autograd import gradcheck

from wise.errors import WiseError
from wise.filters.quantize import quantize

DOUBLE = torch.float64


def _ramp(width: int = 257) -> torch.Tensor:
    return torch.linspace(0.0, 1.0, width, dtype=DOUBLE).view(1, 1, 1, -1)


def _rand(*shape: int, low: float = 0.0, high: float = 1.0, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return torch.rand(*shape, generator=g, dtype=DOUBLE) * (high - low) + low


@pytest.mark.parametrize("bins", [1.0, 2.0, 4.0, 7.0, 10.0])
def test_ramp_has_bins_levels_at_bin_centres(bins: float) -> None:
    levels = quantize(_ramp(), bins).unique()
    assert levels.numel() == int(bins)
    expected = (torch.arange(int(bins), dtype=DOUBLE) + 0.5) / bins
    assert torch.allclose(levels, expected)


def test_fractional_bins_make_a_partial_top_bin() -> None:
    levels = quantize(_ramp(), 4.5).unique()
    assert levels.numel() == 5
    assert levels.max().item() == pytest.approx(1.0)


def test_hard_quantization_of_known_values() -> None:
    x = torch.tensor([0.0, 0.1, 0.26, 0.5, 0.74, 0.99, 1.0], dtype=DOUBLE).view(1, 1, 1, -1)
    expected = torch.tensor([0.125, 0.125, 0.375, 0.625, 0.625, 0.875, 0.875], dtype=DOUBLE)
    assert torch.allclose(quantize(x, 4.0).flatten(), expected)


def test_per_batch_and_per_pixel_bins() -> None:
    x = _ramp(64).expand(2, 3, 4, 64)
    per_batch = quantize(x, torch.tensor([2.0, 5.0], dtype=DOUBLE))
    assert per_batch[0].unique().numel() == 2 and per_batch[1].unique().numel() == 5
    bins_map = torch.full((2, 1, 4, 64), 3.0, dtype=DOUBLE)
    bins_map[:, :, 2:] = 6.0
    per_pixel = quantize(x, bins_map)
    assert per_pixel[:, :, :2].unique().numel() == 3 and per_pixel[:, :, 2:].unique().numel() == 6


def test_soft_tends_to_hard_as_softness_vanishes() -> None:
    x = _rand(1, 3, 16, 16)
    hard = quantize(x, 5.0)
    errors = [(quantize(x, 5.0, softness) - hard).abs().mean().item() for softness in (0.5, 0.1, 0.02, 0.001)]
    assert all(a > b for a, b in zip(errors, errors[1:]))
    assert errors[-1] < 1e-3


def test_soft_is_monotonic_continuous_and_tends_to_identity() -> None:
    x = _ramp(2001)
    for softness in (0.05, 0.3, 1.0):
        y = quantize(x, 4.0, softness).flatten()
        steps = y.diff()
        assert steps.min() >= 0.0 and steps.max() < 0.01  # no jumps, also at bin centres
    assert (quantize(x, 4.0, 50.0) - x).abs().max() < 1e-3
    smoother = [quantize(x, 4.0, s).diff(dim=-1).max().item() for s in (0.05, 0.3, 1.0)]
    assert smoother[0] > smoother[1] > smoother[2]  # steepest step shrinks with softness


def test_hard_image_gradient_is_straight_through() -> None:
    x = _rand(1, 3, 4, 5).requires_grad_()
    quantize(x, 4.0).sum().backward()
    assert torch.equal(x.grad, torch.ones_like(x))


def test_gradcheck_soft_image_and_softness() -> None:
    x = _rand(2, 3, 5, 6).requires_grad_()
    softness = _rand(2, 1, 5, 6, low=0.2, high=0.6, seed=1).requires_grad_()
    assert gradcheck(lambda a, s: quantize(a, 4.0, s), (x, softness), eps=1e-6, nondet_tol=1e-12, atol=1e-5, rtol=1e-3)
    global_softness = torch.tensor([0.3, 0.5], dtype=DOUBLE, requires_grad=True)
    learnable_bins = torch.tensor([3.0, 5.5], dtype=DOUBLE, requires_grad=True)  # numeric gradient, not checked

    def with_learnable_bins(a, s):
        return quantize(a, learnable_bins, s)

    assert gradcheck(with_learnable_bins, (x, global_softness), eps=1e-6, nondet_tol=1e-12, atol=1e-5, rtol=1e-3)


def _bins_gradient(x: torch.Tensor, target: torch.Tensor, bins: torch.Tensor, softness: float = 0.0) -> torch.Tensor:
    bins = bins.clone().requires_grad_()
    ((quantize(x, bins, softness) - target) ** 2).sum().backward()
    return bins.grad


def test_numeric_bins_gradient_points_towards_the_target_bins() -> None:
    x = _rand(2, 3, 16, 16)
    target = quantize(x, torch.tensor([3.0, 9.0], dtype=DOUBLE))
    grad = _bins_gradient(x, target, torch.tensor([6.0, 6.0], dtype=DOUBLE))
    assert grad[0] > 0 and grad[1] < 0  # descent lowers b for image 0, raises it for image 1
    assert _bins_gradient(x, quantize(x, 6.0), torch.tensor(6.0, dtype=DOUBLE)).item() == 0.0
    soft_target = quantize(x, 3.0, 0.2)
    assert _bins_gradient(x, soft_target, torch.tensor(6.0, dtype=DOUBLE), 0.2).item() > 0


def test_numeric_bins_gradient_for_a_per_pixel_map() -> None:
    x = _rand(1, 3, 8, 8)
    target = quantize(x, 3.0)
    bins_map = torch.full((1, 1, 8, 8), 6.0, dtype=DOUBLE)
    grad = _bins_gradient(x, target, bins_map)
    assert grad.shape == bins_map.shape
    assert (grad >= 0).all() and grad.sum() > 0


def test_adam_on_bins_recovers_the_target_bin_count() -> None:
    x = _rand(1, 3, 16, 16)
    target = quantize(x, 4.0)
    bins = torch.tensor(10.0, dtype=DOUBLE, requires_grad=True)
    optimizer = torch.optim.Adam([bins], lr=0.25)
    losses = []
    for _ in range(80):
        optimizer.zero_grad()
        loss = ((quantize(x, bins) - target) ** 2).mean()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    assert abs(bins.item() - 4.0) < 0.5
    assert losses[-1] < losses[0]


@pytest.mark.parametrize(("start", "target_bins", "size"), [(9.0, 5.4, 32), (15.0, 2.46, 32), (3.0, 12.7, 160)])
def test_adam_on_bins_recovers_a_fractional_bin_count(start: float, target_bins: float, size: int) -> None:
    # size 160 scores the candidates on a subsample of the pixels
    x = _rand(1, 3, size, size)
    target = quantize(x, target_bins, 0.1)
    bins = torch.tensor(start, dtype=DOUBLE, requires_grad=True)
    optimizer = torch.optim.Adam([bins], lr=0.2)
    for _ in range(150):
        optimizer.zero_grad()
        ((quantize(x, bins, 0.1) - target) ** 2).mean().backward()
        optimizer.step()
    assert abs(bins.item() - target_bins) < 0.1


def test_bad_arguments() -> None:
    x = _rand(1, 3, 4, 4)
    with pytest.raises(WiseError):
        quantize(x, 0.5)
    with pytest.raises(WiseError):
        quantize(x, 4.0, -0.1)
    with pytest.raises(WiseError):
        quantize(x, torch.ones(3, 3))
