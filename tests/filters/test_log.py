"""Flow-based Laplacian of Gaussian: gradients and answers known on synthetic images."""

import math

import pytest
import torch
from torch.autograd import gradcheck

from wise.filters.log import flow_log

DOUBLE = torch.float64
SIZE = 33
CENTRE = SIZE // 2


def _rand(*shape: int, low: float = 0.0, high: float = 1.0, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return torch.rand(*shape, generator=g, dtype=DOUBLE) * (high - low) + low


def _unit_field(b: int, h: int, w: int, seed: int = 1) -> torch.Tensor:
    angle = _rand(b, 1, h, w, high=2 * math.pi, seed=seed)
    return torch.cat((angle.cos(), angle.sin()), dim=1)


def _unit(v: torch.Tensor) -> torch.Tensor:
    return v / torch.sqrt(v[:, 0:1] ** 2 + v[:, 1:2] ** 2)


def _field(x: float, y: float, size: int = SIZE) -> torch.Tensor:
    return torch.tensor([x, y], dtype=DOUBLE).view(1, 2, 1, 1).expand(1, 2, size, size)


def _vertical(profile: torch.Tensor) -> torch.Tensor:
    """An image varying along x only, constant along y (edges run vertically)."""
    return profile.view(1, 1, 1, -1).expand(1, 1, profile.numel(), profile.numel()).contiguous()


ALONG_Y = _field(0.0, 1.0)  # tangent of vertical edges: the gradient direction is x


@pytest.mark.parametrize("per_pixel", [False, True])
def test_gradcheck(per_pixel: bool) -> None:
    image = _rand(2, 2, 6, 7).requires_grad_()
    tangent = _unit_field(2, 6, 7, seed=3).requires_grad_()
    sigma = _rand(2, 1, 6, 7, low=0.8, high=1.1, seed=4) if per_pixel else _rand(2, low=0.8, high=1.1, seed=4)
    sigma.requires_grad_()
    fn = lambda i, t, s: flow_log(i, _unit(t), s, scale=1.0)  # noqa: E731
    assert gradcheck(fn, (image, tangent, sigma), eps=1e-6, nondet_tol=1e-12, atol=1e-5, rtol=1e-3)


def test_zero_on_constants_and_ramps() -> None:
    tangent = _unit_field(1, SIZE, SIZE)
    constant = torch.full((1, 2, SIZE, SIZE), 0.7, dtype=DOUBLE)
    assert flow_log(constant, tangent, 2.0, scale=1.0).abs().max() < 1e-12
    ys, xs = torch.meshgrid(torch.arange(SIZE, dtype=DOUBLE), torch.arange(SIZE, dtype=DOUBLE), indexing="ij")
    ramp = (0.3 * xs - 0.2 * ys + 1.0).view(1, 1, SIZE, SIZE)
    inner = flow_log(ramp, tangent, 2.0, scale=1.0)[..., 10:-10, 10:-10]
    assert inner.abs().max() < 1e-10


def test_bright_line_gives_a_strong_negative_centre() -> None:
    profile = torch.zeros(SIZE, dtype=DOUBLE)
    profile[CENTRE] = 1.0
    row = flow_log(_vertical(profile), ALONG_Y, 1.0, scale=1.0)[0, 0, CENTRE]
    assert row[CENTRE] < -0.35  # sigma^2 * (G'' * delta)(0) = -1 / sqrt(2 pi) = -0.40
    assert int(row.argmin()) == CENTRE
    assert row[CENTRE - 2] > 0 and row[CENTRE + 2] > 0  # the flanks at two sigma


def test_step_is_negative_on_the_bright_side() -> None:
    step = _vertical((torch.arange(SIZE) >= CENTRE).to(DOUBLE))
    row = flow_log(step, ALONG_Y, 2.0, scale=1.0)[0, 0, CENTRE]
    assert row[CENTRE : CENTRE + 4].max() < -0.1
    assert row[CENTRE - 4 : CENTRE].min() > 0.1
    assert float(row.abs().max()) == pytest.approx(1.0 / math.sqrt(2.0 * math.pi * math.e), rel=0.05)


def test_only_the_gradient_direction_counts() -> None:
    stripes = _vertical(torch.sin(torch.arange(SIZE, dtype=DOUBLE) / 2.0))
    assert flow_log(stripes, _field(1.0, 0.0), 1.5, scale=1.0).abs().max() < 1e-12
    assert flow_log(stripes, ALONG_Y, 1.5, scale=1.0).abs().max() > 0.2


def test_rotating_the_pattern_with_the_tangent_gives_the_same_response() -> None:
    image = _rand(1, 1, SIZE, SIZE, seed=5)
    tangent = _unit_field(1, SIZE, SIZE, seed=6)
    response = flow_log(image, tangent, 1.7, scale=1.0)
    # a quarter turn of the image: (x, y) -> (y, x) mirrors, so the tangent's components swap
    turned = flow_log(image.transpose(-1, -2), tangent.flip(1).transpose(-1, -2), 1.7, scale=1.0)
    assert torch.allclose(turned.transpose(-1, -2), response, atol=1e-12)

    # an eighth turn samples the same smooth profile on the diagonal, sqrt(2) apart
    ys, xs = torch.meshgrid(torch.arange(SIZE, dtype=DOUBLE), torch.arange(SIZE, dtype=DOUBLE), indexing="ij")
    frequency = 0.35
    straight = flow_log(torch.sin(frequency * xs).view(1, 1, SIZE, SIZE), ALONG_Y, 2.0, scale=1.0)
    diagonal_image = torch.sin(frequency * (xs + ys) / math.sqrt(2.0)).view(1, 1, SIZE, SIZE)
    diagonal = flow_log(diagonal_image, _field(1 / math.sqrt(2.0), -1 / math.sqrt(2.0)), 2.0, scale=1.0)
    expected = (
        straight[0, 0, CENTRE, CENTRE]
        * torch.sin(frequency * (xs + ys) / math.sqrt(2.0))
        / math.sin(frequency * CENTRE)
    )
    inner = slice(10, -10)
    amplitude = float(straight[0, 0, CENTRE, inner].abs().max())
    assert (diagonal[0, 0, inner, inner] - expected[inner, inner]).abs().max() < 0.02 * amplitude


def test_same_response_at_every_resolution() -> None:
    def centre_response(size: int) -> float:
        x = torch.arange(size, dtype=DOUBLE) - size // 2
        width = size / 32.0
        line = _vertical(torch.exp(-0.5 * (x / width) ** 2))
        return float(flow_log(line, _field(0.0, 1.0, size), 16.0)[0, 0, size // 2, size // 2])

    small, large = centre_response(64), centre_response(128)
    assert small < -0.2
    assert large == pytest.approx(small, rel=0.03)


def test_larger_sigma_responds_to_wider_lines() -> None:
    x = torch.arange(SIZE, dtype=DOUBLE) - CENTRE
    wide_line = _vertical(torch.exp(-0.5 * (x / 3.0) ** 2))
    narrow = flow_log(wide_line, ALONG_Y, 0.7, scale=1.0)[0, 0, CENTRE, CENTRE]
    matched = flow_log(wide_line, ALONG_Y, 3.0, scale=1.0)[0, 0, CENTRE, CENTRE]
    assert matched < 2.0 * narrow < 0
