import math

import pytest
import torch
import torch.nn.functional as F
from torch.autograd import gradcheck

from wise.errors import WiseError
from wise.filters.shading import bump_phong, phong_highlight

DOUBLE = torch.float64


def _rand(*shape: int, low: float = 0.0, high: float = 1.0, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return (torch.rand(*shape, generator=g, dtype=DOUBLE) * (high - low) + low).requires_grad_()


def _bump(size: int, radius: float) -> torch.Tensor:
    """A Gaussian hill of unit height in the middle of a (1, 1, size, size) map."""
    coords = torch.arange(size, dtype=DOUBLE) - (size - 1) / 2
    squared = coords.view(-1, 1) ** 2 + coords.view(1, -1) ** 2
    return torch.exp(-squared / (2 * radius * radius)).view(1, 1, size, size)


def test_flat_height_gives_ambient_diffuse_and_specular() -> None:
    color = torch.rand(2, 3, 6, 7, dtype=DOUBLE) * 0.5
    light = (1.0, -2.0, 2.0)
    light_z = 2.0 / 3.0
    ambient, diffuse, specular, shininess = 0.2, 0.6, 0.3, 4.0
    flat = torch.full((2, 1, 6, 7), 0.7, dtype=DOUBLE)
    out = bump_phong(color, flat, 5.0, light, ambient, diffuse, specular, shininess)
    expected = color * (ambient + diffuse * light_z) + specular * light_z**shininess
    assert torch.allclose(out, expected)


@pytest.mark.parametrize("light", [(-1.0, -1.0, 1.0), (0.0, -1.0, 1.5), (2.0, 0.5, 0.3)])
@pytest.mark.parametrize("ambient", [0.5, 0.2])
def test_default_diffuse_keeps_flat_colour_under_any_light(light: tuple[float, float, float], ambient: float) -> None:
    color = torch.rand(1, 3, 5, 5, dtype=DOUBLE) * 0.9
    out = bump_phong(color, torch.zeros(1, 1, 5, 5, dtype=DOUBLE), 3.0, light, ambient, specular=0.0)
    assert torch.allclose(out, color)


def test_bump_is_lit_on_the_side_facing_the_light() -> None:
    color = torch.full((1, 3, 33, 33), 0.5, dtype=DOUBLE)
    out = bump_phong(color, _bump(33, 5.0), strength=20.0, specular=0.0, scale=1.0)[0, 0]
    centre, offset = 16, 5
    top_left, bottom_right = out[centre - offset, centre - offset], out[centre + offset, centre + offset]
    assert top_left > out[0, 0] > bottom_right  # light from the top left
    assert torch.allclose(out[centre - offset, centre + offset], out[centre + offset, centre - offset])
    assert out[centre, centre - offset] > out[centre, centre + offset]
    assert out[centre - offset, centre] > out[centre + offset, centre]


def test_strength_zero_is_flat_and_more_strength_more_contrast() -> None:
    color = torch.full((1, 3, 33, 33), 0.5, dtype=DOUBLE)
    height = _bump(33, 5.0)
    flat = bump_phong(color, torch.zeros_like(height), specular=0.0, scale=1.0)
    assert torch.allclose(bump_phong(color, height, 0.0, specular=0.0, scale=1.0), flat)
    spread = [bump_phong(color, height, s, specular=0.0, scale=1.0).std().item() for s in (1.0, 3.0, 9.0)]
    assert spread[0] < spread[1] < spread[2]


def test_specular_highlight_is_white_where_reflection_meets_viewer() -> None:
    color = torch.zeros(1, 3, 33, 33, dtype=DOUBLE)
    out = bump_phong(color, _bump(33, 6.0), 30.0, (0.0, 0.0, 1.0), 0.0, 0.0, 1.0, 8.0, scale=1.0)
    assert out[0, :, 16, 16].tolist() == pytest.approx([1.0, 1.0, 1.0])  # top faces the light and viewer
    assert out[0, 0, 16, 22] < 0.5


def test_strength_means_the_same_at_every_resolution() -> None:
    results = []
    for size in (64, 128):
        height = _bump(size, size / 8.0)  # the same relief at both resolutions
        color = torch.full((1, 3, size, size), 0.5, dtype=DOUBLE)
        out = bump_phong(color, height, strength=40.0, specular=0.0)
        results.append(F.interpolate(out, size=(16, 16), mode="area"))
    assert (results[0] - results[1]).abs().max() < 0.01
    assert results[0].std() > 0.02  # the relief is visible at all


def test_gradcheck_every_input() -> None:
    color = _rand(2, 3, 5, 6, low=0.2, high=0.6)
    height = _rand(2, 1, 5, 6, low=0.0, high=0.1, seed=1)
    strength = _rand(2, 1, 5, 6, low=1.0, high=3.0, seed=2)
    ambient = _rand(2, low=0.2, high=0.3, seed=3)
    diffuse = _rand(2, 1, 5, 6, low=0.3, high=0.5, seed=4)
    specular = _rand(2, low=0.1, high=0.3, seed=5)
    shininess = _rand(2, 1, 5, 6, low=2.0, high=4.0, seed=6)
    light = (-1.0, -1.0, 2.0)  # N.L and R.V stay positive for these gentle slopes

    def fn(c, h, st, a, d, sp, sh):
        return bump_phong(c, h, st, light, a, d, sp, sh, scale=1.0)

    inputs = (color, height, strength, ambient, diffuse, specular, shininess)
    assert gradcheck(fn, inputs, eps=1e-6, nondet_tol=1e-12, atol=1e-5, rtol=1e-3)


def test_gradients_stay_finite_where_clamps_cut() -> None:
    color = torch.rand(1, 3, 9, 9, dtype=DOUBLE)
    height = torch.rand(1, 1, 9, 9, dtype=DOUBLE, requires_grad=True)
    shininess = torch.tensor(10.0, dtype=DOUBLE, requires_grad=True)
    out = bump_phong(color, height, 200.0, (1.0, 0.0, 0.2), shininess=shininess, scale=1.0)
    out.sum().backward()
    assert torch.isfinite(height.grad).all() and torch.isfinite(shininess.grad)


def test_bad_arguments() -> None:
    color = torch.rand(1, 3, 4, 4)
    with pytest.raises(WiseError):
        bump_phong(color, torch.rand(1, 3, 4, 4))
    with pytest.raises(WiseError):
        bump_phong(color, torch.rand(1, 1, 4, 5))
    with pytest.raises(WiseError):
        bump_phong(color, torch.rand(1, 1, 4, 4), light_direction=(0.0, 0.0, 0.0))
    with pytest.raises(WiseError):
        bump_phong(color, torch.rand(1, 1, 4, 4), light_direction=(1.0, 1.0))  # type: ignore[arg-type]


def test_light_direction_need_not_be_unit() -> None:
    color = torch.rand(1, 3, 8, 8, dtype=DOUBLE)
    height = torch.rand(1, 1, 8, 8, dtype=DOUBLE)
    a = bump_phong(color, height, light_direction=(1.0, 2.0, 3.0), scale=1.0)
    b = bump_phong(color, height, light_direction=(2.0, 4.0, 6.0), scale=1.0)
    assert torch.allclose(a, b)
    assert not math.isnan(a.sum().item())


def test_the_highlight_alone_is_bump_phongs_specular_term() -> None:
    height = _bump(33, 6.0)
    for light, shininess in (((0.0, -1.0, 1.5), 8.0), ((-1.0, -1.0, 1.0), 30.0)):
        black = torch.zeros(1, 3, 33, 33, dtype=DOUBLE)
        specular = bump_phong(black, height, 3.0, light, 0.0, 0.0, 1.0, shininess, scale=1.0)[:, :1]
        assert torch.allclose(phong_highlight(height, 3.0, light, shininess, scale=1.0), specular)
    flat = phong_highlight(torch.zeros(1, 1, 9, 9, dtype=DOUBLE), 3.0, (0.0, -1.0, 1.5), 8.0, scale=1.0)
    assert torch.allclose(flat, torch.full_like(flat, (1.5 / math.hypot(1.0, 1.5)) ** 8.0))
