"""The fused Gaussian blur against the PyTorch path."""

import pytest
import torch
from torch.autograd import gradcheck

from tests.filters.helpers import rand
from tests.filters.paths import assert_paths_agree, kernels
from wise.filters.gaussian import gaussian_blur


@pytest.mark.parametrize("sigma", [0.3, 1.5, 7.0])
def test_fixed_blur_matches_torch_in_float64(sigma: float) -> None:
    image = rand(2, 3, 17, 23)
    assert_paths_agree(lambda x: gaussian_blur(x, sigma, scale=1.0), [image], rtol=1e-12)


def test_fixed_blur_matches_torch_in_float32() -> None:
    image = rand(3, 2, 40, 31).detach().float().requires_grad_()
    assert_paths_agree(lambda x: gaussian_blur(x, 2.2, scale=1.0), [image], rtol=1e-6)


def test_fixed_blur_gradcheck() -> None:
    with kernels("fused"):
        assert gradcheck(lambda x: gaussian_blur(x, 1.3, scale=1.0), (rand(1, 2, 6, 9),), eps=1e-6, atol=1e-8)


def test_fused_blur_runs_the_fused_kernel(monkeypatch: pytest.MonkeyPatch) -> None:
    from wise.filters.fused import gaussian as fused_gaussian

    calls = []
    original = fused_gaussian.correlate_axis
    monkeypatch.setattr(fused_gaussian, "correlate_axis", lambda *a, **k: calls.append(a[2]) or original(*a, **k))
    with kernels("fused"):
        gaussian_blur(torch.rand(1, 1, 8, 8), 1.0, scale=1.0)
    with kernels("torch"):
        gaussian_blur(torch.rand(1, 1, 8, 8), 1.0, scale=1.0)
    assert calls == [3, 2]
