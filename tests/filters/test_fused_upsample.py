"""The fused joint bilateral upsampling against the PyTorch path."""

import pytest
import torch
from torch.autograd import gradcheck

from tests.filters.helpers import rand
from tests.filters.paths import assert_paths_agree, kernels, needs_kernels
from wise.filters.upsample import joint_bilateral_upsample

pytestmark = needs_kernels


@pytest.mark.parametrize("radius", [1, 2])
@pytest.mark.parametrize("channels", [(3, 3), (2, 3), (3, 1)])  # the RGB kernels and the generic ones
def test_upsampling_with_maps_matches_torch_in_float64(radius: int, channels: tuple[int, int]) -> None:
    low = rand(2, channels[0], 6, 7)
    guide = rand(2, channels[1], 13, 17, seed=1)
    sigma_spatial = rand(2, 1, 13, 17, low=0.5, high=1.5, seed=2)
    sigma_range = rand(2, 1, 13, 17, low=0.05, high=0.4, seed=3)
    assert_paths_agree(
        lambda *a: joint_bilateral_upsample(*a, radius=radius), [low, guide, sigma_spatial, sigma_range], rtol=1e-9
    )


def test_upsampling_with_per_picture_sigmas_and_other_guide_channels_matches_torch() -> None:
    low = rand(2, 2, 5, 4)
    guide = rand(2, 1, 11, 9, seed=1)
    sigma_spatial = rand(2, low=0.7, high=1.2, seed=2)
    sigma_range = rand(1, 1, 1, 1, low=0.1, high=0.3, seed=3)
    assert_paths_agree(joint_bilateral_upsample, [low, guide, sigma_spatial, sigma_range], rtol=1e-9)


def test_upsampling_where_the_weights_reach_their_floors_matches_torch() -> None:
    # a tiny range sigma sends most range exponents below their floor, a tiny spatial sigma the
    # far neighbours' exponents below theirs
    low = rand(2, 3, 4, 5)
    guide = rand(2, 3, 12, 15, seed=1)
    sigma_spatial = rand(2, 1, 12, 15, low=0.2, high=0.3, seed=2)
    sigma_range = rand(2, 1, 12, 15, low=0.002, high=0.05, seed=3)
    assert_paths_agree(joint_bilateral_upsample, [low, guide, sigma_spatial, sigma_range], rtol=1e-9)


def test_upsampling_with_float_sigmas_matches_torch() -> None:
    low = rand(1, 3, 8, 8)
    guide = rand(1, 3, 16, 16, seed=1)
    assert_paths_agree(lambda lo, g: joint_bilateral_upsample(lo, g, 1.0, 0.2), [low, guide], rtol=1e-9)


def test_upsampling_matches_torch_in_float32() -> None:
    low = (rand(2, 3, 20, 16) * 100).detach().float().requires_grad_()
    guide = (rand(2, 3, 40, 31, seed=1) * 100).detach().float().requires_grad_()
    sigma_range = rand(2, 1, 40, 31, low=5.0, high=20.0, seed=2).detach().float().requires_grad_()
    assert_paths_agree(lambda lo, g, r: joint_bilateral_upsample(lo, g, 1.0, r), [low, guide, sigma_range], rtol=1e-5)


def test_upsampling_without_gradients_matches_torch() -> None:
    low = rand(2, 3, 9, 10).detach()
    guide = rand(2, 3, 20, 23, seed=1).detach()
    with kernels("torch"):
        expected = joint_bilateral_upsample(low, guide, 1.0, 0.1)
    with kernels("fused"):
        result = joint_bilateral_upsample(low, guide, 1.0, 0.1)
    assert torch.allclose(result, expected, rtol=0.0, atol=1e-12)


@pytest.mark.parametrize("channels", [3, 2])
def test_upsampling_gradcheck(channels: int) -> None:
    low = rand(2, channels, 3, 4)
    guide = rand(2, channels, 5, 7, seed=1)
    sigma_spatial = rand(2, 1, 5, 7, low=0.8, high=1.2, seed=2)
    sigma_range = rand(2, low=0.4, high=0.8, seed=3)
    with kernels("fused"):
        assert gradcheck(
            lambda *a: joint_bilateral_upsample(*a, radius=2),
            (low, guide, sigma_spatial, sigma_range),
            eps=1e-6,
            nondet_tol=1e-12,
            atol=1e-6,
        )


def test_the_fused_upsampling_runs_only_when_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    from wise.filters.fused import upsample as fused_upsample

    calls = []
    for name in ("_forward_rgb", "_forward_any"):
        original = getattr(fused_upsample, name)
        monkeypatch.setattr(
            fused_upsample, name, lambda *a, name=name, original=original: calls.append(name) or original(*a)
        )
    for path in ("fused", "torch"):
        with kernels(path):
            joint_bilateral_upsample(torch.rand(1, 3, 4, 4), torch.rand(1, 3, 8, 8))
            joint_bilateral_upsample(torch.rand(1, 1, 4, 4), torch.rand(1, 3, 8, 8))
    assert calls == ["_forward_rgb", "_forward_any"]
