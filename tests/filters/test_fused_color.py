"""The fused colour conversions (one Dr.Jit kernel per pass) against the PyTorch path."""

import pytest
import torch
from torch.autograd import gradcheck

from tests.filters.helpers import rand
from tests.filters.paths import assert_paths_agree, kernels, needs_kernels
from wise.filters.clamp import inward_gradients
from wise.filters.color import adjust_color, lab_to_rgb, linear_to_srgb, rgb_to_lab, srgb_to_linear

pytestmark = needs_kernels


def _lab(seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    lab = torch.stack(
        (
            torch.rand(2, 9, 11, generator=g, dtype=torch.float64) * 100.0,
            torch.rand(2, 9, 11, generator=g, dtype=torch.float64) * 160.0 - 80.0,
            torch.rand(2, 9, 11, generator=g, dtype=torch.float64) * 160.0 - 80.0,
        ),
        dim=1,
    )
    return lab.requires_grad_()


@pytest.mark.parametrize("dtype, rtol", [(torch.float64, 1e-9), (torch.float32, 2e-5)])
def test_rgb_to_lab_matches_torch(dtype: torch.dtype, rtol: float) -> None:
    image = rand(2, 3, 9, 11).detach().to(dtype).requires_grad_()
    assert_paths_agree(rgb_to_lab, [image], rtol=rtol)


@pytest.mark.parametrize("clip", [True, False])
@pytest.mark.parametrize("dtype, rtol", [(torch.float64, 1e-9), (torch.float32, 2e-5)])
def test_lab_to_rgb_matches_torch(clip: bool, dtype: torch.dtype, rtol: float) -> None:
    lab = _lab().detach().to(dtype).requires_grad_()
    assert_paths_agree(lambda x: lab_to_rgb(x, clip=clip), [lab], rtol=rtol)


@pytest.mark.parametrize("function", [srgb_to_linear, linear_to_srgb])
def test_the_transfer_functions_match_torch(function) -> None:
    # both sides of the linear segment, one channel and four
    assert_paths_agree(function, [rand(2, 4, 7, 5, low=-0.01, high=0.2)], rtol=1e-9)
    assert_paths_agree(function, [rand(1, 1, 7, 5, seed=2)], rtol=1e-9)


def test_round_trip_and_gradcheck_on_the_fused_path() -> None:
    image = rand(1, 3, 5, 6, low=0.05, high=0.95)
    with kernels("fused"):
        back = lab_to_rgb(rgb_to_lab(image), clip=False)
        assert torch.allclose(back, image, atol=1e-9)
        assert gradcheck(lambda x: lab_to_rgb(rgb_to_lab(x), clip=False), (image,), eps=1e-6, atol=1e-6)


def _amounts(per_pixel: bool) -> list[torch.Tensor]:
    """brightness, contrast, saturation, gamma, exposure, hue_shift, temperature, tint: some pixels
    pushed out of range, the saturation past its limit, the hue turned past a whole turn."""
    ranges = [(-0.3, 0.3), (0.5, 1.8), (0.0, 2.5), (0.5, 2.0), (0.7, 1.4), (-0.6, 0.9), (-0.2, 0.2), (-0.2, 0.2)]
    shape = (2, 1, 9, 11) if per_pixel else (2,)
    return [rand(*shape, low=low, high=high, seed=10 + i) for i, (low, high) in enumerate(ranges)]


@pytest.mark.parametrize("per_pixel", [False, True])
@pytest.mark.parametrize("dtype, rtol", [(torch.float64, 1e-9), (torch.float32, 5e-5)])
def test_adjust_color_matches_torch(per_pixel: bool, dtype: torch.dtype, rtol: float) -> None:
    image = rand(2, 3, 9, 11).detach()
    image[:, :, 0, :3] = 0.5  # grey pixels: no chroma, no hue
    image = image.to(dtype).requires_grad_()
    amounts = [a.detach().to(dtype).requires_grad_() for a in _amounts(per_pixel)]
    assert_paths_agree(lambda i, *a: adjust_color(i, *a), [image, *amounts], rtol=rtol)


def test_adjust_color_with_neutral_numbers_and_a_batch_of_one() -> None:
    image = rand(1, 3, 6, 5)
    assert_paths_agree(lambda i, b: adjust_color(i, brightness=b, contrast=1.3, gamma=1.0), [image, rand(1)], rtol=1e-9)


def test_adjust_color_keeps_the_inward_gradients_of_the_pytorch_path() -> None:
    image = rand(1, 3, 6, 5)
    brightness = rand(1, 1, 6, 5, low=0.5, high=1.0)  # pushes most pixels above white

    def gradient(path: str, inward: bool) -> torch.Tensor:
        with kernels(path), inward_gradients(inward):
            return torch.autograd.grad(adjust_color(image, brightness=brightness).sum(), brightness)[0]

    inward = gradient("fused", inward=True)
    assert torch.equal(inward, gradient("torch", inward=True))
    assert (inward != 0).all()  # saturated pixels pass a gradient back
    assert (gradient("fused", inward=False) == 0).any()  # which a plain clamp does not
