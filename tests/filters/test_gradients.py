"""Every filter's analytic gradients against finite differences (float64, tiny images)."""

import pytest
import torch
from torch.autograd import gradcheck

from tests.filters.helpers import DOUBLE, rand, unit, unit_field
from wise import filters as W


def _check(fn, *inputs: torch.Tensor) -> None:
    assert gradcheck(fn, inputs, eps=1e-6, nondet_tol=1e-12, atol=1e-5, rtol=1e-3)


def test_adjust_color() -> None:
    image = rand(2, 3, 5, 6, low=0.1, high=0.8)
    brightness = rand(2, low=-0.05, high=0.05, seed=2)
    contrast = rand(2, 1, 5, 6, low=0.8, high=1.2, seed=3)
    saturation = rand(2, low=0.5, high=0.9, seed=4)
    gamma = rand(2, low=0.8, high=1.2, seed=5)
    exposure = rand(2, low=0.9, high=1.1, seed=6)
    hue = rand(2, low=0.05, high=0.1, seed=7)
    _check(lambda *a: W.adjust_color(*a), image, brightness, contrast, saturation, gamma, exposure, hue)


def test_lab_round_trip_gradients() -> None:
    _check(W.rgb_to_lab, rand(1, 3, 4, 5, low=0.05, high=0.95))
    lab = W.rgb_to_lab(rand(1, 3, 4, 5, low=0.2, high=0.8).detach()).requires_grad_()
    _check(W.lab_to_rgb, lab)


def test_hsv_gradients() -> None:
    _check(W.rgb_to_hsv, rand(1, 3, 4, 5, low=0.1, high=0.9))
    hsv = torch.stack(
        [torch.rand(1, 4, 5) * 0.9 + 0.02, torch.rand(1, 4, 5) * 0.6 + 0.2, torch.rand(1, 4, 5) * 0.6 + 0.3], 1
    )
    _check(W.hsv_to_rgb, hsv.to(DOUBLE).requires_grad_())


@pytest.mark.parametrize("per_pixel", [False, True])
def test_gaussian_blur(per_pixel: bool) -> None:
    image = rand(2, 2, 7, 8)
    sigma = rand(2, 1, 7, 8, low=0.6, high=1.4, seed=3) if per_pixel else rand(2, low=0.6, high=1.4, seed=3)
    _check(lambda i, s: W.gaussian_blur(i, s, scale=1.0), image, sigma)


@pytest.mark.parametrize("sigma", [0.7, 3.0, 9.0])
def test_fixed_gaussian_blur_analytic_backward(sigma: float) -> None:
    # a global sigma takes the separable convolution with its own backward (and, from 6 pixels,
    # the pyramid); the kernel may be wider than the image
    _check(lambda i: W.gaussian_blur(i, sigma, scale=1.0), rand(2, 2, 7, 9))


@pytest.mark.parametrize("distance", [1.0, 2.0])
def test_structure_tensor_at_whole_pixels_matches_sampling(distance: float) -> None:
    image = rand(2, 3, 9, 10)
    fast = W.structure_tensor(image, distance, scale=1.0)
    sampled = W.structure_tensor(image, torch.tensor(distance, dtype=DOUBLE), scale=1.0)
    upstream = torch.randn_like(fast)
    (grad_fast,) = torch.autograd.grad(fast, image, upstream)
    (grad_sampled,) = torch.autograd.grad(sampled, image, upstream)
    torch.testing.assert_close(fast, sampled, rtol=0, atol=1e-12)
    torch.testing.assert_close(grad_fast, grad_sampled, rtol=0, atol=1e-12)
    _check(lambda i: W.structure_tensor(i, distance, scale=1.0), image)


def test_structure_tensor() -> None:
    image = rand(2, 1, 7, 8)
    sigma = rand(2, 1, 7, 8, low=0.55, high=0.9, seed=4)
    _check(lambda i, s: W.structure_tensor(i, s, scale=1.0), image, sigma)


def test_edge_tangent_flow() -> None:
    tensor = rand(1, 3, 5, 6, low=0.1, high=2.0)
    _check(W.edge_tangent_flow, tensor)


def test_bilateral_pass() -> None:
    image = rand(2, 3, 7, 8, high=20.0)
    direction = unit_field(2, 7, 8)
    sigma_d = rand(2, low=1.9, high=2.6, seed=5)
    sigma_r = rand(2, 1, 7, 8, low=5.0, high=15.0, seed=6)
    _check(lambda i, d, a, b: W.bilateral_pass(i, unit(d), a, b, 3, 1.0), image, direction, sigma_d, sigma_r)


def test_oriented_bilateral() -> None:
    image = rand(1, 3, 6, 7, high=20.0)
    tangent = unit_field(1, 6, 7, seed=8)
    sigma_d = rand(1, 1, 6, 7, low=1.1, high=1.4, seed=9)
    _check(lambda i, t, a: W.oriented_bilateral(i, unit(t), a, 12.0, 2, 1.0), image, tangent, sigma_d)


def test_flow_dog() -> None:
    image = rand(2, 1, 7, 8)
    tangent = unit_field(2, 7, 8, seed=3)
    sigma = rand(2, 1, 7, 8, low=0.8, high=1.1, seed=4)
    sharpen = rand(2, low=1.0, high=5.0, seed=5)
    _check(lambda i, t, s, p: W.flow_dog(i, unit(t), s, p, 10, 1.0), image, tangent, sigma, sharpen)


def test_flow_smoothing() -> None:
    image = rand(2, 2, 7, 8)
    tangent = unit_field(2, 7, 8, seed=6).detach()
    sigma = rand(2, 1, 7, 8, low=1.1, high=1.4, seed=7)
    _check(lambda i, s: W.flow_smoothing(i, tangent, s, scale=1.0), image, sigma)


def test_xdog_threshold() -> None:
    response = rand(1, 1, 5, 6)
    epsilon = rand(1, 1, 5, 6, low=0.3, high=0.7, seed=3)
    sharpness = rand(1, low=2.0, high=4.0, seed=4)
    _check(W.xdog_threshold, response, epsilon, sharpness)


def test_inward_clamp_lets_saturated_values_come_back() -> None:
    from wise.filters.clamp import inward_clamp, inward_gradients

    values = torch.tensor([-0.5, -0.5, 0.5, 1.5, 1.5], dtype=DOUBLE, requires_grad=True)
    upstream = torch.tensor([-1.0, 1.0, 1.0, -1.0, 1.0], dtype=DOUBLE)
    (plain,) = torch.autograd.grad(inward_clamp(values), values, upstream)
    assert plain.tolist() == [0.0, 0.0, 1.0, 0.0, 0.0]  # outside the context: a plain clamp
    with inward_gradients():
        clamped = inward_clamp(values)
    (grad,) = torch.autograd.grad(clamped, values, upstream)
    assert torch.equal(clamped, values.clamp(0.0, 1.0))
    # a descent step (-grad) that moves a saturated value towards the range passes; one that
    # would move it further out is turned back towards the range
    assert grad.tolist() == [-1.0, -1.0, 1.0, 1.0, 1.0]
