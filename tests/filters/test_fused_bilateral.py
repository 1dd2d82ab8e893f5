"""The fused bilateral filter (forward and backward) against the PyTorch path."""

import pytest
import torch
from torch.autograd import gradcheck

from tests.filters.helpers import rand, unit, unit_field
from tests.filters.paths import assert_paths_agree, assert_scatters_repeat, kernels, needs_kernels
from wise.filters.bilateral import bilateral, bilateral_pass, oriented_bilateral

pytestmark = needs_kernels


@pytest.mark.parametrize("per_pixel", [False, True])
@pytest.mark.parametrize("samples", [1, 3])
def test_bilateral_pass_matches_torch_in_float64(per_pixel: bool, samples: int) -> None:
    image = rand(2, 3, 13, 17, high=50.0)
    direction = unit_field(2, 13, 17)
    sigma_d = rand(2, 1, 13, 17, low=0.5, high=4.0, seed=3) if per_pixel else rand(2, low=1.0, high=3.0, seed=3)
    sigma_r = rand(2, 1, 13, 17, low=5.0, high=20.0, seed=4) if per_pixel else rand(2, low=5.0, high=9.0, seed=4)
    assert_paths_agree(
        lambda i, d, s, r: bilateral_pass(i, unit(d), s, r, samples=samples, scale=1.0),
        [image, direction, sigma_d, sigma_r],
        rtol=1e-9,
    )


def test_bilateral_pass_with_one_channel_and_a_shared_direction_matches_torch() -> None:
    # a (1, 2, H, W) direction broadcast over the batch, global sigmas as floats
    image = rand(2, 1, 9, 11, high=10.0)
    direction = unit_field(1, 9, 11, seed=5)
    assert_paths_agree(lambda i, d: bilateral_pass(i, d, 2.5, 3.0, scale=1.0), [image, direction], rtol=1e-9)


def test_oriented_bilateral_matches_torch_in_float32() -> None:
    image = rand(2, 3, 40, 36, high=100.0).detach().float().requires_grad_()
    tangent = unit_field(2, 40, 36).detach().float().requires_grad_()
    sigma_d = rand(2, 1, 40, 36, low=1.0, high=6.0, seed=5).detach().float().requires_grad_()
    sigma_r = rand(2, 1, 40, 36, low=4.0, high=12.0, seed=6).detach().float().requires_grad_()
    # the PyTorch path's own float32 error is up to 1.3e-5 (tangent gradient, against float64); the
    # kernel's 2.5e-6, as it computes in float64 between the float32 loads and stores
    assert_paths_agree(
        lambda i, t, s, r: oriented_bilateral(i, t, s, r, 3, scale=1.0), [image, tangent, sigma_d, sigma_r], rtol=3e-5
    )


def test_axis_aligned_bilateral_matches_torch() -> None:
    # whole-pixel steps: the samples fall on pixel rows and columns, including the image's last one
    image = rand(2, 3, 12, 10, high=30.0)
    assert_paths_agree(lambda i: bilateral(i, 3.0, 8.0, scale=1.0), [image], rtol=1e-9)


def test_bilateral_gradcheck() -> None:
    image = rand(2, 2, 6, 7, high=3.0)
    direction = unit_field(2, 6, 7)
    sigma_d = rand(2, 1, 6, 7, low=0.8, high=2.5, seed=2)
    sigma_r = rand(2, low=1.0, high=2.0, seed=3)
    with kernels("fused"):
        assert gradcheck(
            lambda i, d, s, r: bilateral_pass(i, unit(d), s, r, samples=2, scale=1.0),
            (image, direction, sigma_d, sigma_r),
            eps=1e-6,
            nondet_tol=1e-12,
            atol=1e-6,
        )


def test_fused_backward_repeats_on_one_thread_and_within_rounding_on_two() -> None:
    image = rand(2, 3, 24, 20, high=50.0).detach().float().requires_grad_()
    direction = unit_field(2, 24, 20).detach().float()
    assert_scatters_repeat(lambda i: bilateral_pass(i, direction, 3.0, 8.0, scale=1.0).square().sum(), image)


def test_the_fused_kernel_runs_only_when_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    from wise.filters.fused import bilateral as fused_bilateral

    calls = []
    for name in ("_forward", "_backward"):
        original = getattr(fused_bilateral, name)
        monkeypatch.setattr(fused_bilateral, name, lambda *a, f=original, n=name: calls.append(n) or f(*a))
    image = torch.rand(1, 3, 8, 8, requires_grad=True)
    direction = unit_field(1, 8, 8).detach().float()
    for path in ("fused", "torch"):
        with kernels(path):
            bilateral_pass(image, direction, 2.0, 5.0, scale=1.0).sum().backward()
    assert calls == ["_forward", "_backward"]
