"""The fused flow filters of wise.filters.dog against the PyTorch path."""

import pytest
import torch
from torch.autograd import gradcheck

from tests.filters.helpers import rand, unit, unit_field
from tests.filters.paths import assert_paths_agree, kernels, needs_kernels
from wise.filters.dog import flow_dog, flow_smoothing

pytestmark = needs_kernels


def smooth_field(b: int, h: int, w: int, dtype=torch.float64) -> torch.Tensor:
    """A slowly turning unit field (streamlines that curve), as edge flows are."""
    ys, xs = torch.meshgrid(torch.arange(h, dtype=dtype), torch.arange(w, dtype=dtype), indexing="ij")
    angle = 0.15 * xs + 0.1 * ys + torch.arange(b, dtype=dtype).view(b, 1, 1)
    return torch.stack((angle.cos(), angle.sin()), dim=1)


@pytest.mark.parametrize("per_pixel", [False, True])
def test_flow_smoothing_matches_torch_in_float64(per_pixel: bool) -> None:
    image = rand(2, 2, 15, 18)
    tangent = smooth_field(2, 15, 18)
    sigma = rand(2, 1, 15, 18, low=0.5, high=4.0, seed=3) if per_pixel else rand(2, low=1.0, high=3.0, seed=3)
    assert_paths_agree(lambda i, s: flow_smoothing(i, tangent, s, max_steps=8, scale=1.0), [image, sigma], rtol=1e-9)


def test_flow_smoothing_on_a_random_field_and_a_broadcast_tangent() -> None:
    image = rand(2, 1, 12, 11)
    tangent = unit_field(1, 12, 11).detach()
    assert_paths_agree(lambda i: flow_smoothing(i, tangent, 2.5, max_steps=6, scale=1.0), [image], rtol=1e-9)


def test_flow_smoothing_matches_torch_in_float32() -> None:
    image = rand(2, 1, 48, 40).detach().float().requires_grad_()
    tangent = smooth_field(2, 48, 40, torch.float32)
    sigma = rand(2, 1, 48, 40, low=1.0, high=6.0, seed=5).detach().float().requires_grad_()
    assert_paths_agree(lambda i, s: flow_smoothing(i, tangent, s, scale=1.0), [image, sigma], rtol=2e-5)


def test_flow_smoothing_gradcheck() -> None:
    image = rand(2, 2, 6, 7)
    sigma = rand(2, 1, 6, 7, low=1.1, high=1.4, seed=2)  # no support cut-off within reach of eps
    with kernels("fused"):
        assert gradcheck(
            lambda i, s: flow_smoothing(i, smooth_field(2, 6, 7), s, max_steps=4, scale=1.0),
            (image, sigma),
            eps=1e-6,
            nondet_tol=1e-12,
            atol=1e-6,
        )


def test_the_fused_smoothing_runs_only_when_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    from wise.filters.fused import dog as fused_dog

    calls = []
    original = fused_dog._smoothing_forward
    monkeypatch.setattr(fused_dog, "_smoothing_forward", lambda *a: calls.append(1) or original(*a))
    image, tangent = torch.rand(1, 1, 8, 8), smooth_field(1, 8, 8, torch.float32)
    for path in ("fused", "torch"):
        with kernels(path):
            flow_smoothing(image, tangent, 2.0, scale=1.0)
    assert calls == [1]


@pytest.mark.parametrize("per_pixel", [False, True])
def test_flow_dog_matches_torch_in_float64(per_pixel: bool) -> None:
    image = rand(2, 1, 14, 17)
    tangent = unit_field(2, 14, 17, seed=4)
    sigma = rand(2, 1, 14, 17, low=0.4, high=1.5, seed=5) if per_pixel else rand(2, low=0.5, high=1.2, seed=5)
    sharpen = rand(2, 1, 14, 17, low=10.0, high=100.0, seed=6) if per_pixel else 50.0
    inputs = [image, tangent, sigma] + ([sharpen] if per_pixel else [])

    def fn(image, tangent, sigma, *rest):
        return flow_dog(image, unit(tangent), sigma, rest[0] if rest else sharpen, max_steps=6, scale=1.0)

    assert_paths_agree(fn, inputs, rtol=1e-9)


def test_flow_dog_matches_torch_in_float32() -> None:
    image = rand(3, 1, 40, 36).detach().float().requires_grad_()
    tangent = unit_field(3, 40, 36).detach().float().requires_grad_()
    assert_paths_agree(lambda i, t: flow_dog(i, t, 1.0, 100.0, scale=1.0), [image, tangent], rtol=2e-5)


def test_flow_dog_gradcheck() -> None:
    image = rand(2, 2, 6, 7)
    tangent = unit_field(2, 6, 7, seed=2)
    sigma = rand(2, 1, 6, 7, low=0.6, high=0.9, seed=3)
    with kernels("fused"):
        assert gradcheck(
            lambda i, t, s: flow_dog(i, unit(t), s, 20.0, max_steps=3, scale=1.0),
            (image, tangent, sigma),
            eps=1e-6,
            nondet_tol=1e-12,
            atol=1e-5,
        )


def test_flow_dog_gradient_of_the_tangent_alone() -> None:
    image = rand(2, 2, 12, 13).detach()
    tangent = unit_field(2, 12, 13, seed=7)
    sigma = rand(2, 1, 12, 13, low=0.5, high=1.5, seed=8)
    assert_paths_agree(lambda i, t, s: flow_dog(i, unit(t), s, 30.0, scale=1.0), [image, tangent, sigma], rtol=1e-9)


def test_the_fused_dog_runs_only_when_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    from wise.filters.fused import dog as fused_dog

    calls = []
    original = fused_dog._dog_forward
    monkeypatch.setattr(fused_dog, "_dog_forward", lambda *a: calls.append(1) or original(*a))
    image, tangent = torch.rand(1, 1, 8, 8), unit_field(1, 8, 8).detach().float()
    for path in ("fused", "torch"):
        with kernels(path):
            flow_dog(image, tangent, 1.0, 20.0, scale=1.0)
    assert calls == [1]
