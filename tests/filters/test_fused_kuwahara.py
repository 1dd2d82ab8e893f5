"""The fused sector blend of the anisotropic Kuwahara filter against the PyTorch path."""

import pytest
import torch
from torch.autograd import gradcheck

from tests.filters.helpers import rand
from tests.filters.paths import assert_paths_agree, kernels
from wise.filters.kuwahara import anisotropic_kuwahara
from wise.filters.structure import smoothed_structure_tensor


def _tensor(image: torch.Tensor) -> torch.Tensor:
    return smoothed_structure_tensor(image.detach(), 1.0, 2.0, scale=1.0)


@pytest.mark.parametrize("per_pixel", [False, True])
def test_kuwahara_matches_torch_in_float64(per_pixel: bool) -> None:
    image = rand(2, 3, 14, 15)
    tensor = _tensor(image).requires_grad_()
    radius = rand(2, 1, 14, 15, low=1.0, high=4.0, seed=3) if per_pixel else rand(2, low=2.0, high=4.0, seed=3)
    sharpness = rand(2, 1, 14, 15, low=4.0, high=10.0, seed=4) if per_pixel else rand(2, low=6.0, high=9.0, seed=4)
    assert_paths_agree(
        lambda i, t, r, q: anisotropic_kuwahara(i, t, r, q, scale=1.0), [image, tensor, radius, sharpness], 1e-9
    )


def test_kuwahara_matches_torch_in_float32() -> None:
    image = rand(2, 3, 32, 30).detach().float().requires_grad_()
    radius = rand(2, 1, 32, 30, low=2.0, high=6.0, seed=5).detach().float().requires_grad_()
    assert_paths_agree(
        lambda i, r: anisotropic_kuwahara(i, _tensor(i), r, scale=1.0, samples_per_sector=2), [image, radius], 2e-5
    )


def test_kuwahara_gradcheck() -> None:
    image = rand(1, 2, 6, 7)
    tensor = _tensor(image).requires_grad_()
    sharpness = rand(1, 1, 6, 7, low=4.0, high=9.0, seed=6)
    with kernels("fused"):
        assert gradcheck(
            lambda i, t, q: anisotropic_kuwahara(i, t, 2.0, q, scale=1.0, sectors=4, samples_per_sector=2),
            (image, tensor, sharpness),
            eps=1e-6,
            atol=1e-5,
        )


def test_the_fused_blend_runs_only_when_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    from wise.filters.fused import kuwahara as fused_kuwahara

    calls = []
    original = fused_kuwahara._blend_forward
    monkeypatch.setattr(fused_kuwahara, "_blend_forward", lambda *a: calls.append(1) or original(*a))
    image = torch.rand(1, 3, 8, 8)
    for path in ("fused", "torch"):
        with kernels(path):
            anisotropic_kuwahara(image, _tensor(image), 2.0, scale=1.0)
    assert calls == [1]
