"""Bilinear resizing: PyTorch's values, the same bits on one thread and on two."""

import pytest
import torch
import torch.nn.functional as F
from torch.autograd import gradcheck

from wise.filters.resize import bilinear_resize

CASES = [
    ((1, 3, 72, 64), (576, 512)),  # whole factors: the interleaved phases
    ((2, 1, 7, 5), (56, 40)),
    ((1, 2, 10, 10), (13, 7)),  # other ratios: gathers
    ((1, 1, 1, 1), (4, 4)),
    ((1, 1, 30, 40), (30, 80)),
    ((1, 1, 2, 3), (6, 9)),
]


@pytest.mark.parametrize(("shape", "size"), CASES)
def test_the_values_are_pytorchs_bilinear(shape: tuple, size: tuple) -> None:
    image = torch.rand(shape, dtype=torch.float64, generator=torch.Generator().manual_seed(sum(shape)))
    expected = F.interpolate(image, size=size, mode="bilinear", align_corners=False)
    torch.testing.assert_close(bilinear_resize(image, size), expected, rtol=0, atol=1e-12)


@pytest.mark.parametrize("size", [(576, 512), (571, 509)])
def test_one_thread_and_two_give_the_same_bits(size: tuple) -> None:
    image = torch.rand(1, 3, 72, 64, generator=torch.Generator().manual_seed(1))
    before = torch.get_num_threads()
    try:
        results = []
        for threads in (1, 2):
            torch.set_num_threads(threads)
            results.append(bilinear_resize(image, size))
    finally:
        torch.set_num_threads(before)
    assert torch.equal(results[0], results[1])


def test_gradients() -> None:
    image = torch.rand(1, 2, 4, 3, dtype=torch.float64, requires_grad=True)
    assert gradcheck(lambda x: bilinear_resize(x, (8, 9)), (image,))
    assert gradcheck(lambda x: bilinear_resize(x, (5, 7)), (image,))
