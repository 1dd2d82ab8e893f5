"""The fused candidate scores of quantize's numeric bins gradient against the PyTorch path."""

import importlib

import pytest
import torch

from tests.filters.helpers import rand
from tests.filters.paths import assert_paths_agree, kernels, needs_kernels
from wise.filters.quantize import MIN_BINS, quantize

pytestmark = needs_kernels

quantize_module = importlib.import_module("wise.filters.quantize")


def _torch_scores(x, y, grad, bins, softness, offsets):
    signs = grad.sign().reshape(len(x), -1, 1)
    scores = []
    for offset in offsets:
        levels = quantize_module._levels(x, quantize_module._candidate(bins, offset), softness)
        scores.append(torch.bmm((y - levels).sign().reshape(len(x), 1, -1), signs).view(len(x)))
    return torch.stack(scores)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("soft", [True, False])
def test_candidate_scores_equal_the_torch_scores(dtype: torch.dtype, soft: bool) -> None:
    from wise.filters.fused.quantize import candidate_scores

    x = rand(3, 2, 33, 41, seed=1).detach().to(dtype)
    bins = rand(3, 1, 33, 41, low=1.0, high=9.0, seed=2).detach().to(dtype)
    softness = rand(3, 1, 33, 41, low=0.05, high=0.8, seed=3).detach().to(dtype) if soft else None
    y = quantize_module._levels(x, bins, softness) + 0.01 * (rand(3, 2, 33, 41, seed=4).detach().to(dtype) - 0.5)
    grad = torch.randn(3, 2, 33, 41, generator=torch.Generator().manual_seed(5), dtype=dtype)
    grad[grad.abs() < 0.3] = 0.0
    offsets = [step for step in quantize_module._candidate_steps() if step is not None]
    fused_scores = candidate_scores(x, y, grad, bins, softness, offsets, MIN_BINS)
    assert torch.equal(fused_scores, _torch_scores(x, y, grad, bins, softness, offsets))


@pytest.mark.parametrize("bins_shape", [(2, 1, 18, 23), (1, 1, 18, 23), (2,), (1,)])
def test_bins_gradient_matches_torch_soft(bins_shape: tuple[int, ...]) -> None:
    image = rand(2, 3, 18, 23, seed=6)
    bins = rand(*bins_shape, low=3.0, high=7.0, seed=7)
    softness = rand(2, 1, 18, 23, low=0.1, high=0.6, seed=8)
    assert_paths_agree(lambda x, b, s: quantize(x, b, s), [image, bins, softness], rtol=1e-12)


def test_bins_gradient_matches_torch_hard_in_float32() -> None:
    image = rand(2, 1, 30, 26, seed=9).detach().float().requires_grad_()
    bins = rand(2, 1, 30, 26, low=2.0, high=9.0, seed=10).detach().float().requires_grad_()
    assert_paths_agree(lambda x, b: quantize(x, b), [image, bins], rtol=1e-6)


def test_the_fused_scores_run_only_when_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    from wise.filters.fused import quantize as fused_quantize

    calls = []
    original = fused_quantize._candidate_scores
    monkeypatch.setattr(fused_quantize, "_candidate_scores", lambda *a: calls.append(1) or original(*a))
    for path in ("fused", "torch"):
        with kernels(path):
            bins = torch.full((1, 1, 8, 8), 4.0, requires_grad=True)
            quantize(torch.rand(1, 1, 8, 8), bins, 0.2).sum().backward()
    assert calls == [1]
