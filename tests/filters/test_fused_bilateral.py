"""The fused backward pass of the bilateral filter against the PyTorch path."""

import pytest
import torch
from torch.autograd import gradcheck

from tests.filters.helpers import rand, unit_field
from tests.filters.paths import assert_paths_agree, kernels
from wise.filters.bilateral import bilateral_pass, oriented_bilateral


@pytest.mark.parametrize("per_pixel", [False, True])
def test_bilateral_gradients_match_torch_in_float64(per_pixel: bool) -> None:
    image = rand(2, 3, 13, 17, high=50.0)
    direction = unit_field(2, 13, 17)
    sigma_d = rand(2, 1, 13, 17, low=0.5, high=4.0, seed=3) if per_pixel else rand(2, low=1.0, high=3.0, seed=3)
    sigma_r = rand(2, 1, 13, 17, low=5.0, high=20.0, seed=4) if per_pixel else rand(2, low=5.0, high=9.0, seed=4)
    assert_paths_agree(
        lambda i, d, s, r: bilateral_pass(i, d, s, r, samples=3, scale=1.0), [image, direction, sigma_d, sigma_r], 1e-9
    )


def test_oriented_bilateral_gradients_match_torch_in_float32() -> None:
    image = rand(2, 3, 40, 36, high=100.0).detach().float().requires_grad_()
    tangent = unit_field(1, 40, 36).detach().float().requires_grad_()
    sigma_d = rand(2, 1, 40, 36, low=1.0, high=6.0, seed=5).detach().float().requires_grad_()
    assert_paths_agree(lambda i, t, s: oriented_bilateral(i, t, s, 8.0, 3, scale=1.0), [image, tangent, sigma_d], 2e-5)


def test_bilateral_gradcheck() -> None:
    image = rand(2, 2, 6, 7, high=3.0)
    direction = unit_field(2, 6, 7)
    sigma_d = rand(2, 1, 6, 7, low=0.8, high=2.5, seed=2)
    sigma_r = rand(2, low=1.0, high=2.0, seed=3)
    with kernels("fused"):
        assert gradcheck(
            lambda *a: bilateral_pass(*a, samples=2, scale=1.0),
            (image, direction, sigma_d, sigma_r),
            eps=1e-6,
            atol=1e-6,
        )


def test_the_fused_backward_runs_only_when_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    from wise.filters.fused import bilateral as fused_bilateral

    calls = []
    original = fused_bilateral._backward
    monkeypatch.setattr(fused_bilateral, "_backward", lambda *a: calls.append(1) or original(*a))
    image = torch.rand(1, 3, 8, 8, requires_grad=True)
    direction = unit_field(1, 8, 8).detach().float()
    for path in ("fused", "torch"):
        with kernels(path):
            bilateral_pass(image, direction, 2.0, 5.0, scale=1.0).sum().backward()
    assert calls == [1]
