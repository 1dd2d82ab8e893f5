"""The fixed blur's banded matrix products against the depthwise convolution."""

import pytest
import torch
from torch.autograd import gradcheck, gradgradcheck

from wise.filters import banded
from wise.filters.gaussian import _correlate_axis, _fixed_kernel, _FixedBlurAxis, gaussian_blur

SHAPES = [(2, 3, 17, 23), (1, 2, 1, 9), (1, 1, 5, 1), (2, 1, 3, 70), (1, 1, 130, 2), (1, 2, 67, 33)]


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("sigma", [0.3, 1.5, 7.0, 20.0])
@pytest.mark.parametrize("axis", [2, 3])
def test_the_blur_and_its_gradient_are_the_convolutions(shape: tuple, sigma: float, axis: int) -> None:
    # lines shorter than the kernel, of one pixel, and over several blocks with a partial last one
    generator = torch.Generator().manual_seed(len(shape) + int(sigma) + axis)
    image = torch.rand(shape, dtype=torch.float64, generator=generator).requires_grad_()
    kernel = _fixed_kernel(sigma, image)
    reference = _correlate_axis(image, kernel, axis, "replicate")
    out = _FixedBlurAxis.apply(image, kernel, axis)
    torch.testing.assert_close(out, reference, rtol=1e-12, atol=1e-14)
    upstream = torch.rand(out.shape, dtype=out.dtype, generator=generator)
    (expected,) = torch.autograd.grad(reference, image, upstream)
    (got,) = torch.autograd.grad(out, image, upstream)
    torch.testing.assert_close(got, expected, rtol=1e-12, atol=1e-14)


def test_float32_agrees_with_the_convolution() -> None:
    image = torch.rand(2, 3, 150, 97)
    for sigma in (1.0, 6.0):
        kernel = _fixed_kernel(sigma, image)
        for axis in (2, 3):
            expected = _correlate_axis(image, kernel, axis, "replicate")
            torch.testing.assert_close(banded.correlate_axis(image, kernel, axis), expected, rtol=1e-6, atol=1e-6)


def test_gradients_of_first_and_second_order() -> None:
    image = torch.rand(1, 2, 6, 9, dtype=torch.float64, requires_grad=True)
    assert gradcheck(lambda x: gaussian_blur(x, 1.3, scale=1.0), (image,), eps=1e-6, atol=1e-8)
    assert gradgradcheck(lambda x: gaussian_blur(x, 1.3, scale=1.0), (image,), eps=1e-6, atol=1e-8)


def test_the_band_holds_the_kernel_on_its_diagonals() -> None:
    kernel = torch.tensor([1.0, 2.0, 3.0, 2.0, 1.0])
    band = banded._toeplitz(kernel, 4)
    assert band.shape == (8, 4)
    for j in range(4):
        assert band[j : j + 5, j].tolist() == kernel.tolist()
        assert band[:, j].sum() == kernel.sum()
