"""The fused sampled structure tensor against the PyTorch path."""

import pytest
import torch
from torch.autograd import gradcheck

from tests.filters.helpers import rand
from tests.filters.paths import assert_paths_agree, kernels, needs_kernels
from wise.filters.structure import structure_tensor

pytestmark = needs_kernels


@pytest.mark.parametrize("per_pixel", [False, True])
def test_structure_tensor_matches_torch_in_float64(per_pixel: bool) -> None:
    image = rand(2, 2, 14, 17)
    sigma = rand(2, 1, 14, 17, low=0.3, high=2.5, seed=3) if per_pixel else rand(2, low=0.4, high=1.7, seed=3)
    assert_paths_agree(lambda i, s: structure_tensor(i, s, scale=1.0), [image, sigma], rtol=1e-9)


def test_a_fractional_global_distance_matches_torch_in_float32() -> None:
    image = rand(3, 1, 40, 33).detach().float().requires_grad_()
    assert_paths_agree(lambda i: structure_tensor(i, 0.7, scale=1.0), [image], rtol=2e-5)


def test_structure_tensor_gradcheck() -> None:
    image = rand(2, 2, 6, 7)
    sigma = rand(2, 1, 6, 7, low=0.3, high=0.9, seed=2)
    with kernels("fused"):
        assert gradcheck(
            lambda i, s: structure_tensor(i, s, scale=1.0), (image, sigma), eps=1e-6, nondet_tol=1e-12, atol=1e-6
        )


def test_the_fused_sobel_runs_only_when_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    from wise.filters.fused import structure as fused_structure

    calls = []
    original = fused_structure._tensor_forward
    monkeypatch.setattr(fused_structure, "_tensor_forward", lambda *a: calls.append(1) or original(*a))
    for path in ("fused", "torch"):
        with kernels(path):
            structure_tensor(torch.rand(1, 1, 8, 8), 0.6, scale=1.0)
    assert calls == [1]


@pytest.mark.parametrize("dtype, rtol", [(torch.float64, 1e-9), (torch.float32, 2e-5)])
def test_edge_tangent_flow_matches_torch(dtype: torch.dtype, rtol: float) -> None:
    from wise.filters.structure import edge_tangent_flow

    tensor = rand(2, 3, 9, 11, low=-1.0, high=1.0).detach()
    tensor[:, 1, 0, :4] = 0.0  # isotropic: the direction rests on the epsilon
    tensor[:, 0, 0, :4] = tensor[:, 2, 0, :4]
    assert_paths_agree(edge_tangent_flow, [tensor.to(dtype).requires_grad_()], rtol=rtol)
