"""The fused procedural noise (one Dr.Jit kernel) against the PyTorch path."""

import pytest
import torch

from tests.filters.paths import kernels, needs_kernels
from wise.filters.noise import paper_texture, value_noise

pytestmark = needs_kernels


def _both(render) -> tuple[torch.Tensor, torch.Tensor]:
    with kernels("torch"):
        reference = render()
    with kernels("fused"):
        fused = render()
    return reference, fused


@pytest.mark.parametrize("dtype, tolerance", [(torch.float64, 1e-12), (torch.float32, 1e-6)])
@pytest.mark.parametrize("origin", [(0, 0), (-37, 1200)])
def test_value_noise_matches_torch(dtype: torch.dtype, tolerance: float, origin: tuple[int, int]) -> None:
    like = torch.zeros(2, 3, 45, 61, dtype=dtype)
    reference, fused = _both(lambda: value_noise(like, 7.5, seed=11, octaves=4, origin=origin, scale=0.8))
    assert fused.shape == reference.shape == (2, 1, 45, 61) and fused.dtype == dtype
    assert float((fused - reference).abs().max()) <= tolerance


@pytest.mark.parametrize("dtype, tolerance", [(torch.float64, 1e-12), (torch.float32, 2e-6)])
def test_paper_texture_matches_torch(dtype: torch.dtype, tolerance: float) -> None:
    like = torch.zeros(1, 3, 70, 52, dtype=dtype)
    reference, fused = _both(lambda: paper_texture(like, seed=5, grain=2.5, origin=(13, -8), scale=1.7))
    assert float((fused - reference).abs().max()) <= tolerance
    assert 0.05 < float(fused.std())  # a texture, not a constant
