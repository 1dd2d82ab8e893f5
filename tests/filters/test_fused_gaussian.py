"""The fused Gaussian blur of a per-pixel sigma against the PyTorch path."""

import pytest
import torch
from torch.autograd import gradcheck

from tests.filters.helpers import rand
from tests.filters.paths import assert_paths_agree, kernels, needs_kernels
from wise.filters.gaussian import gaussian_blur

pytestmark = needs_kernels


@pytest.mark.parametrize("batch_of_sigma", [1, 2])
def test_varying_blur_matches_torch_in_float64(batch_of_sigma: int) -> None:
    image = rand(2, 3, 17, 23)
    sigma = rand(batch_of_sigma, 1, 17, 23, low=0.05, high=3.5, seed=4)
    assert_paths_agree(lambda x, s: gaussian_blur(x, s, scale=1.0), [image, sigma], rtol=1e-9)


def test_varying_blur_with_a_sigma_per_picture_matches_torch() -> None:
    image = rand(2, 1, 12, 9)
    sigma = rand(2, low=0.5, high=2.5, seed=5)
    assert_paths_agree(lambda x, s: gaussian_blur(x, s, scale=1.0), [image, sigma], rtol=1e-9)


def test_varying_blur_matches_torch_in_float32() -> None:
    image = rand(2, 2, 40, 31).detach().float().requires_grad_()
    sigma = rand(2, 1, 40, 31, low=0.2, high=4.0, seed=6).detach().float().requires_grad_()
    assert_paths_agree(lambda x, s: gaussian_blur(x, s, scale=1.0), [image, sigma], rtol=1e-5)


def test_varying_blur_gradcheck() -> None:
    image = rand(2, 2, 7, 6)
    sigma = rand(2, 1, 7, 6, low=0.3, high=2.0, seed=7)
    with kernels("fused"):
        assert gradcheck(lambda x, s: gaussian_blur(x, s, scale=1.0), (image, sigma), eps=1e-6, atol=1e-7)


def test_varying_blur_runs_the_fused_kernel_only_when_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    from wise.filters.fused import gaussian as fused_gaussian

    calls = []
    original = fused_gaussian._varying_lines
    monkeypatch.setattr(fused_gaussian, "_varying_lines", lambda *a: calls.append(1) or original(*a))
    sigma = torch.full((1, 1, 8, 8), 1.2)
    for path in ("fused", "torch"):
        with kernels(path):
            gaussian_blur(torch.rand(1, 1, 8, 8), sigma, scale=1.0)
    assert calls == [1, 1]
