"""One flow field may serve a batch of images: the flow DoG broadcasts it on both paths."""

import pytest
from torch.autograd import gradcheck

from tests.filters.helpers import rand, unit, unit_field
from tests.filters.paths import kernels
from wise.filters.dog import flow_dog


@pytest.mark.parametrize("path", ["torch", "fused"])
def test_flow_dog_with_one_tangent_for_a_batch(path: str) -> None:
    image = rand(2, 1, 6, 7)
    tangent = unit_field(1, 6, 7, seed=2)
    sigma = rand(2, 1, 6, 7, low=0.6, high=0.9, seed=3)
    with kernels(path):
        assert gradcheck(
            lambda i, t, s: flow_dog(i, unit(t), s, 20.0, max_steps=3, scale=1.0),
            (image, tangent, sigma),
            eps=1e-6,
            nondet_tol=1e-12,
            atol=1e-5,
        )
