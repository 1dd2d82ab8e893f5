"""The fused wet-in-wet bleeding and gaps and overlaps against the PyTorch path."""

import pytest
import torch
from torch.autograd import gradcheck

from tests.filters.helpers import rand, unit, unit_field
from tests.filters.paths import assert_paths_agree, kernels, needs_kernels
from wise.filters.watercolor import gaps_overlaps, wet_in_wet

pytestmark = needs_kernels


@pytest.mark.parametrize("samples", [1, 6])
def test_wet_in_wet_with_maps_matches_torch_in_float64(samples: int) -> None:
    image = rand(2, 3, 13, 17)
    direction = unit_field(2, 13, 17)
    edges = rand(2, 1, 13, 17, seed=3)
    amount = rand(2, 1, 13, 17, low=0.5, high=8.0, seed=4)  # far enough to reach the border
    noise = rand(2, 1, 13, 17, seed=5)

    def fn(image, direction, edges, amount, noise):
        return wet_in_wet(image, unit(direction), edges, amount, noise, scale=1.0, samples=samples)

    assert_paths_agree(fn, [image, direction, edges, amount, noise], rtol=1e-9)


def test_wet_in_wet_with_floats_and_a_broadcast_direction_matches_torch() -> None:
    image = rand(2, 2, 11, 9)
    direction = unit_field(1, 11, 9, seed=2)
    assert_paths_agree(lambda i, d: wet_in_wet(i, d, 0.7, 3.0, 0.4, scale=1.0), [image, direction], rtol=1e-9)


def test_wet_in_wet_with_per_picture_parameters_matches_torch() -> None:
    image = rand(2, 3, 10, 12)
    direction = unit_field(2, 10, 12, seed=2).detach()
    edges = rand(2, low=0.2, high=0.9, seed=3)
    amount = rand(2, low=1.0, high=4.0, seed=4)
    fn = lambda i, e, a: wet_in_wet(i, direction, e, a, 0.5, scale=1.0)  # noqa: E731
    assert_paths_agree(fn, [image, edges, amount], rtol=1e-9)


def test_wet_in_wet_matches_torch_in_float32() -> None:
    image = rand(2, 3, 40, 31).detach().float().requires_grad_()
    direction = unit_field(2, 40, 31).detach().float().requires_grad_()
    edges = rand(2, 1, 40, 31, seed=3).detach().float().requires_grad_()
    amount = rand(2, 1, 40, 31, low=1.0, high=6.0, seed=4).detach().float().requires_grad_()
    fn = lambda i, d, e, a: wet_in_wet(i, d, e, a, 0.5, scale=1.0)  # noqa: E731
    assert_paths_agree(fn, [image, direction, edges, amount], rtol=2e-5)


def test_wet_in_wet_gradcheck() -> None:
    image = rand(2, 2, 6, 7)
    direction = unit_field(2, 6, 7, seed=2)
    edges = rand(2, 1, 6, 7, seed=3)
    amount = rand(2, 1, 6, 7, low=1.0, high=3.0, seed=4)
    with kernels("fused"):
        assert gradcheck(
            lambda i, d, e, a: wet_in_wet(i, d, e, a, 0.5, scale=1.0, samples=3),
            (image, direction, edges, amount),
            eps=1e-6,
            nondet_tol=1e-12,
            atol=1e-6,
        )


def test_the_fused_wet_in_wet_runs_only_when_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    from wise.filters.fused import watercolor as fused_watercolor

    calls = []
    original = fused_watercolor._wet_forward
    monkeypatch.setattr(fused_watercolor, "_wet_forward", lambda *a: calls.append(1) or original(*a))
    image, direction = torch.rand(1, 3, 8, 8), unit_field(1, 8, 8).detach().float()
    for path in ("fused", "torch"):
        with kernels(path):
            wet_in_wet(image, direction, 0.5, 2.0, 0.5, scale=1.0)
    assert calls == [1]


@pytest.mark.parametrize("amount_sign", [-1.0, 1.0, 0.0])
def test_gaps_overlaps_with_maps_matches_torch_in_float64(amount_sign: float) -> None:
    image = rand(2, 3, 13, 17)
    edges = rand(2, 1, 13, 17, seed=2)
    direction = unit_field(2, 13, 17, seed=3)
    # amounts of both signs, or of one
    amount = rand(2, 1, 13, 17, low=-1.0, high=1.0, seed=4)
    amount = amount if amount_sign == 0.0 else (amount.detach().abs() * amount_sign).requires_grad_()
    noise = rand(2, 1, 13, 17, seed=5)

    def fn(image, edges, direction, amount, noise):
        return gaps_overlaps(image, edges, unit(direction), amount, noise, scale=1.5, width=2.5)

    assert_paths_agree(fn, [image, edges, direction, amount, noise], rtol=1e-9)


def test_gaps_overlaps_with_floats_and_a_broadcast_direction_matches_torch() -> None:
    image = rand(2, 2, 9, 11)
    direction = unit_field(1, 9, 11, seed=2)
    assert_paths_agree(lambda i, d: gaps_overlaps(i, 0.8, d, 0.6, 0.7, scale=1.0), [image, direction], rtol=1e-9)


def test_gaps_overlaps_with_per_picture_parameters_matches_torch() -> None:
    image = rand(2, 3, 10, 8)
    direction = unit_field(2, 10, 8, seed=2).detach()
    edges = rand(2, low=0.2, high=0.9, seed=3)
    amount = rand(2, low=-1.0, high=1.0, seed=4)
    fn = lambda i, e, a: gaps_overlaps(i, e, direction, a, 0.5, scale=1.0)  # noqa: E731
    assert_paths_agree(fn, [image, edges, amount], rtol=1e-9)


def test_gaps_overlaps_matches_torch_in_float32() -> None:
    image = rand(2, 3, 40, 31).detach().float().requires_grad_()
    edges = rand(2, 1, 40, 31, seed=2).detach().float().requires_grad_()
    direction = unit_field(2, 40, 31, seed=3).detach().float().requires_grad_()
    amount = rand(2, 1, 40, 31, low=-1.0, high=1.0, seed=4).detach().float().requires_grad_()
    # a width of 1.7 keeps the samples off whole pixels, where the slope of the bilinear
    # interpolation jumps and the two paths' float32 rounding of the position could pick either side
    fn = lambda i, e, d, a: gaps_overlaps(i, e, d, a, 0.5, scale=1.0, width=1.7)  # noqa: E731
    assert_paths_agree(fn, [image, edges, direction, amount], rtol=2e-5)


def test_gaps_overlaps_gradcheck() -> None:
    image = rand(2, 2, 6, 7)
    edges = rand(2, 1, 6, 7, seed=2)
    direction = unit_field(2, 6, 7, seed=3)
    amount = rand(2, 1, 6, 7, low=-1.0, high=1.0, seed=4)
    with kernels("fused"):
        assert gradcheck(
            lambda i, e, d, a: gaps_overlaps(i, e, d, a, 0.6, scale=1.0, width=1.7),
            (image, edges, direction, amount),
            eps=1e-6,
            nondet_tol=1e-12,
            atol=1e-6,
        )


def test_the_fused_gaps_overlaps_runs_only_when_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    from wise.filters.fused import watercolor as fused_watercolor

    calls = []
    original = fused_watercolor._gaps_forward
    monkeypatch.setattr(fused_watercolor, "_gaps_forward", lambda *a: calls.append(1) or original(*a))
    image, direction = torch.rand(1, 3, 8, 8), unit_field(1, 8, 8).detach().float()
    for path in ("fused", "torch"):
        with kernels(path):
            gaps_overlaps(image, 0.5, direction, 0.3, 0.5, scale=1.0)
    assert calls == [1]
