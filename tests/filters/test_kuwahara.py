"""The anisotropic Kuwahara filter: gradients and behaviour on images whose answer is known."""

import pytest
import torch
from torch.autograd import gradcheck

from wise.errors import WiseError
from wise.filters.gaussian import gaussian_blur
from wise.filters.kuwahara import _sample_layout, anisotropic_kuwahara
from wise.filters.structure import smoothed_structure_tensor

DOUBLE = torch.float64
SIZE = 48
EDGE_COLUMN = SIZE // 2
NOISE_STD = 0.03
DARK, BRIGHT = 0.2, 0.8


def _rand(*shape: int, low: float = 0.0, high: float = 1.0, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return torch.rand(*shape, generator=g, dtype=DOUBLE) * (high - low) + low


def _noisy_step(seed: int = 0) -> torch.Tensor:
    """A vertical step edge (dark left, bright right) in three channels with Gaussian noise."""
    g = torch.Generator().manual_seed(seed)
    image = torch.full((1, 3, SIZE, SIZE), DARK)
    image[..., EDGE_COLUMN:] = BRIGHT
    return image + NOISE_STD * torch.randn(image.shape, generator=g)


def _tensor(image: torch.Tensor) -> torch.Tensor:
    return smoothed_structure_tensor(image, 1.0, 2.0, scale=1.0)


def _flat_noise_std(image: torch.Tensor) -> float:
    """Noise left in the dark half, away from the edge and the border."""
    return float(image[..., 8:-8, 6 : EDGE_COLUMN - 8].std())


def test_gradients_of_image_and_structure_tensor() -> None:
    image = _rand(1, 2, 6, 7).requires_grad_()
    tensor = _tensor(_rand(1, 2, 6, 7, seed=1)).detach().requires_grad_()

    def fn(image, tensor):
        return anisotropic_kuwahara(image, tensor, 2.3, 7.0, 1.2, scale=1.0, samples_per_sector=2)

    assert gradcheck(fn, (image, tensor), eps=1e-6, nondet_tol=1e-12, atol=1e-5, rtol=1e-3)


def test_gradients_of_per_batch_parameters() -> None:
    image = _rand(2, 2, 5, 6, seed=2)
    tensor = _tensor(_rand(2, 2, 5, 6, seed=3))
    radius = torch.tensor([1.7, 2.3], dtype=DOUBLE, requires_grad=True)
    sharpness = torch.tensor([6.0, 8.0], dtype=DOUBLE, requires_grad=True)
    strength = torch.tensor([0.8, 1.5], dtype=DOUBLE, requires_grad=True)

    def fn(radius, sharpness, strength):
        return anisotropic_kuwahara(image, tensor, radius, sharpness, strength, scale=1.0)

    assert gradcheck(fn, (radius, sharpness, strength), eps=1e-6, nondet_tol=1e-12, atol=1e-5, rtol=1e-3)


def test_gradients_of_parameter_maps() -> None:
    image = _rand(1, 2, 5, 6, seed=4)
    tensor = _tensor(_rand(1, 1, 5, 6, seed=5))
    radius = _rand(1, 1, 5, 6, low=1.2, high=2.4, seed=6).requires_grad_()
    sharpness = _rand(1, 1, 5, 6, low=4.0, high=9.0, seed=7).requires_grad_()
    strength = _rand(1, 1, 5, 6, low=0.5, high=2.0, seed=8).requires_grad_()

    def fn(radius, sharpness, strength):
        return anisotropic_kuwahara(image, tensor, radius, sharpness, strength, scale=1.0, samples_per_sector=2)

    assert gradcheck(fn, (radius, sharpness, strength), eps=1e-6, nondet_tol=1e-12, atol=1e-5, rtol=1e-3)


@pytest.mark.parametrize(("sectors", "samples_per_sector"), [(8, 3), (6, 5), (4, 1)])
def test_sample_layout_weighs_every_sector_alike(sectors: int, samples_per_sector: int) -> None:
    taps = _sample_layout(sectors, samples_per_sector)
    assert len(taps) == sectors * samples_per_sector
    per_sector = [0.0] * sectors
    for tap in taps:
        assert 0.0 < tap.along**2 + tap.across**2 < 1.0
        assert sum(weight for _, weight in tap.sector_weights) == pytest.approx(1.0)
        for sector, weight in tap.sector_weights:
            per_sector[sector] += weight
    assert per_sector == pytest.approx([float(samples_per_sector)] * sectors)


def test_constant_image_stays_constant() -> None:
    constant = torch.full((2, 3, 20, 24), 0.3)
    tensor = _tensor(torch.rand(2, 3, 20, 24, generator=torch.Generator().manual_seed(0)))
    out = anisotropic_kuwahara(constant, tensor, 5.0, scale=1.0)
    assert torch.allclose(out, constant, atol=1e-6)


def test_step_edge_stays_sharp_while_flat_noise_is_reduced() -> None:
    image = _noisy_step()
    radius = 4.0
    out = anisotropic_kuwahara(image, _tensor(image), radius, scale=1.0)
    blurred = gaussian_blur(image, radius, scale=1.0)

    def edge_contrast(x: torch.Tensor) -> float:
        rows = x[..., 8:-8, :]
        return float(rows[..., EDGE_COLUMN + 1].mean() - rows[..., EDGE_COLUMN - 2].mean())

    step = BRIGHT - DARK
    assert edge_contrast(out) > 0.95 * step
    assert edge_contrast(blurred) < 0.8 * step
    assert _flat_noise_std(out) < 0.5 * _flat_noise_std(image)


def test_larger_radius_smooths_more() -> None:
    image = _noisy_step(seed=1)
    tensor = _tensor(image)
    small = anisotropic_kuwahara(image, tensor, 1.5, scale=1.0)
    large = anisotropic_kuwahara(image, tensor, 5.0, scale=1.0)
    assert (small - large).abs().max() > 0.01
    assert _flat_noise_std(large) < 0.8 * _flat_noise_std(small)


def test_radius_map_matches_float_radius() -> None:
    image = _noisy_step(seed=2)
    tensor = _tensor(image)
    by_float = anisotropic_kuwahara(image, tensor, 3.5, scale=1.0)
    by_map = anisotropic_kuwahara(image, tensor, torch.full((1, 1, SIZE, SIZE), 3.5), scale=1.0)
    by_batch = anisotropic_kuwahara(image, tensor, torch.tensor([3.5]), scale=1.0)
    assert torch.allclose(by_float, by_map, atol=1e-6)
    assert torch.allclose(by_float, by_batch, atol=1e-6)


def test_radius_is_in_reference_pixels() -> None:
    image = _noisy_step(seed=3)[..., :32, :40]
    tensor = _tensor(image)
    by_default = anisotropic_kuwahara(image, tensor, 48.0)  # short side 32 px: scale 1/16
    in_pixels = anisotropic_kuwahara(image, tensor, 3.0, scale=1.0)
    assert torch.allclose(by_default, in_pixels, atol=1e-6)


def test_ellipse_follows_the_edge_tangent() -> None:
    """Horizontal stripes survive a kernel stretched along them but not one stretched across them."""
    rows = torch.arange(SIZE, dtype=torch.float32)
    stripes = ((rows // 3) % 2).view(1, 1, SIZE, 1).expand(1, 3, SIZE, SIZE).contiguous()
    along = _tensor(stripes)
    across = along.flip(1)  # swaps fx*fx and fy*fy: the same tensor turned by 90 degrees

    def contrast(tensor: torch.Tensor) -> float:
        out = anisotropic_kuwahara(stripes, tensor, 3.0, scale=1.0)[..., 8:-8, 8:-8]
        return float((out - stripes[..., 8:-8, 8:-8]).abs().mean())

    assert contrast(along) < 0.05
    assert contrast(across) > 0.2


def test_rejects_a_structure_tensor_of_the_wrong_shape() -> None:
    image = torch.rand(1, 3, 10, 12)
    with pytest.raises(WiseError):
        anisotropic_kuwahara(image, torch.rand(1, 2, 10, 12), 3.0)
    with pytest.raises(WiseError):
        anisotropic_kuwahara(image, torch.rand(1, 3, 11, 12), 3.0)
