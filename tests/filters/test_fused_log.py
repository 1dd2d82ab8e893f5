"""The fused flow-based Laplacian of Gaussian against the PyTorch path."""

import pytest
import torch
from torch.autograd import gradcheck

from tests.filters.helpers import rand, unit, unit_field
from tests.filters.paths import assert_paths_agree, kernels, needs_kernels
from wise.filters.log import flow_log

pytestmark = needs_kernels


@pytest.mark.parametrize("per_pixel", [False, True])
def test_flow_log_matches_torch_in_float64(per_pixel: bool) -> None:
    image = rand(2, 2, 13, 16)
    tangent = unit_field(2, 13, 16, seed=4)
    sigma = rand(2, 1, 13, 16, low=0.6, high=3.0, seed=5) if per_pixel else rand(2, low=0.8, high=2.5, seed=5)
    assert_paths_agree(lambda i, t, s: flow_log(i, unit(t), s, scale=1.0), [image, tangent, sigma], rtol=1e-9)


def test_flow_log_matches_torch_in_float32() -> None:
    image = rand(2, 1, 40, 36).detach().float().requires_grad_()
    tangent = unit_field(1, 40, 36, seed=2).detach().float().requires_grad_()
    assert_paths_agree(lambda i, t: flow_log(i, t, 1.5, scale=1.0), [image, tangent], rtol=2e-5)


def test_flow_log_gradient_of_the_tangent_alone() -> None:
    image = rand(2, 1, 12, 13).detach()
    tangent = unit_field(1, 12, 13, seed=7)
    sigma = rand(2, 1, 12, 13, low=0.6, high=2.0, seed=8).detach()
    assert_paths_agree(lambda i, t: flow_log(i, unit(t), sigma, scale=1.0), [image, tangent], rtol=1e-9)


def test_flow_log_gradcheck() -> None:
    image = rand(2, 1, 6, 7)
    tangent = unit_field(2, 6, 7, seed=3)
    sigma = rand(2, 1, 6, 7, low=0.8, high=1.1, seed=6)  # no support cut-off within reach of eps
    with kernels("fused"):
        assert gradcheck(
            lambda i, t, s: flow_log(i, unit(t), s, scale=1.0),
            (image, tangent, sigma),
            eps=1e-6,
            nondet_tol=1e-12,
            atol=1e-5,
        )


def test_the_fused_log_runs_only_when_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    from wise.filters.fused import log as fused_log

    calls = []
    original = fused_log._log_forward
    monkeypatch.setattr(fused_log, "_log_forward", lambda *a: calls.append(1) or original(*a))
    tangent = unit_field(1, 8, 8).detach().float()
    for path in ("fused", "torch"):
        with kernels(path):
            flow_log(torch.rand(1, 1, 8, 8), tangent, 1.0, scale=1.0)
    assert calls == [1]
