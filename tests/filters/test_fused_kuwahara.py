"""The fused anisotropic Kuwahara filter (sample loop and sector blend) against the PyTorch path."""

import pytest
import torch
from torch.autograd import gradcheck

from tests.filters.helpers import rand
from tests.filters.paths import assert_paths_agree, assert_scatters_repeat, kernels, needs_kernels
from wise.filters.kuwahara import _sample_layout, anisotropic_kuwahara
from wise.filters.structure import smoothed_structure_tensor

pytestmark = needs_kernels

FLOAT64_RTOL = 1e-9
FLOAT32_RTOL = 1e-5


def _tensor(image: torch.Tensor) -> torch.Tensor:
    """The structure tensor of ``image``, always from the PyTorch path (only this filter is compared)."""
    with kernels("torch"):
        return smoothed_structure_tensor(image.detach(), 1.0, 2.0, scale=1.0)


@pytest.mark.parametrize("per_pixel", [False, True])
def test_matches_torch_in_float64(per_pixel: bool) -> None:
    image = rand(2, 3, 14, 15)
    tensor = _tensor(image).requires_grad_()
    size = (2, 1, 14, 15) if per_pixel else (2,)
    radius = rand(*size, low=1.0, high=5.0, seed=3)
    sharpness = rand(*size, low=4.0, high=10.0, seed=4)
    strength = rand(*size, low=0.5, high=2.0, seed=5)
    assert_paths_agree(
        lambda i, t, r, q, a: anisotropic_kuwahara(i, t, r, q, a, scale=1.0),
        [image, tensor, radius, sharpness, strength],
        FLOAT64_RTOL,
    )


@pytest.mark.parametrize(("sectors", "samples_per_sector"), [(8, 2), (6, 5), (4, 1)])
def test_layouts_match_torch(sectors: int, samples_per_sector: int) -> None:
    image = rand(1, 2, 11, 13, seed=6)
    radius = rand(1, 1, 11, 13, low=0.5, high=6.0, seed=7)
    assert_paths_agree(
        lambda i, r: anisotropic_kuwahara(
            i, _tensor(i), r, scale=1.0, sectors=sectors, samples_per_sector=samples_per_sector
        ),
        [image, radius],
        FLOAT64_RTOL,
    )


@pytest.mark.parametrize("sharpness", [8.0, 7.0, 30.0, 200.0])
def test_sharpness_by_power_by_exp_and_above_the_softplus_threshold(sharpness: float) -> None:
    """``q / 2`` whole (raised by multiplications) or not, and ``q`` so large that every sector
    lies above the softplus threshold (200: beyond the range of whole powers)."""
    image = rand(2, 3, 10, 11, seed=20)
    radius = rand(2, 1, 10, 11, low=1.0, high=4.0, seed=21)
    q = torch.tensor([sharpness, sharpness + 2.0], dtype=torch.float64, requires_grad=True)
    assert_paths_agree(
        lambda i, r, q: anisotropic_kuwahara(i, _tensor(i), r, q, scale=1.0), [image, radius, q], FLOAT64_RTOL
    )


def test_parameters_broadcast_from_one_picture() -> None:
    """A batch-1 structure tensor and ``(1, 1, H, W)`` maps against a batch of 2 pictures."""
    image = rand(2, 3, 9, 10, seed=8)
    tensor = _tensor(image[:1]).requires_grad_()
    radius = rand(1, 1, 9, 10, low=1.0, high=4.0, seed=9)
    sharpness = rand(1, 1, 1, 1, low=5.0, high=9.0, seed=10)
    assert_paths_agree(
        lambda i, t, r, q: anisotropic_kuwahara(i, t, r, q, scale=1.0), [image, tensor, radius, sharpness], 1e-9
    )


def test_gradients_of_the_parameters_alone() -> None:
    """No gradient for the image: backward skips the scatter."""
    image = rand(2, 3, 9, 10, seed=22).detach()
    radius = rand(2, 1, 9, 10, low=1.0, high=4.0, seed=23)
    strength = rand(2, low=0.5, high=2.0, seed=24)
    assert_paths_agree(
        lambda r, a: anisotropic_kuwahara(image, _tensor(image), r, 7.0, a, scale=1.0), [radius, strength], 1e-9
    )


def test_matches_torch_in_float32() -> None:
    image = rand(2, 3, 32, 30).detach().float().requires_grad_()
    radius = rand(2, 1, 32, 30, low=2.0, high=6.0, seed=11).detach().float().requires_grad_()
    sharpness = rand(2, 1, 32, 30, low=4.0, high=10.0, seed=12).detach().float().requires_grad_()
    assert_paths_agree(
        lambda i, r, q: anisotropic_kuwahara(i, _tensor(i), r, q, scale=1.0, samples_per_sector=2),
        [image, radius, sharpness],
        FLOAT32_RTOL,
        1e-6,
    )


def test_samples_beyond_the_border_and_a_zero_radius() -> None:
    """Ellipses larger than the picture clamp at its border; a zero radius gives the image back."""
    image = rand(1, 3, 7, 8, seed=13)
    radius = rand(1, 1, 7, 8, low=0.0, high=12.0, seed=14)
    assert_paths_agree(lambda i, r: anisotropic_kuwahara(i, _tensor(i), r, scale=1.0), [image, radius], 1e-9)
    with kernels("fused"):
        out = anisotropic_kuwahara(image, _tensor(image), 0.0, scale=1.0)
    assert torch.allclose(out, image, atol=1e-12)


def test_gradcheck() -> None:
    image = rand(1, 2, 6, 7)
    tensor = _tensor(image).requires_grad_()
    radius = rand(1, 1, 6, 7, low=1.0, high=3.0, seed=15)
    sharpness = rand(1, 1, 6, 7, low=4.0, high=9.0, seed=16)
    strength = rand(1, low=0.5, high=2.0, seed=17)
    with kernels("fused"):
        assert gradcheck(
            lambda i, t, r, q, a: anisotropic_kuwahara(i, t, r, q, a, scale=1.0, sectors=4, samples_per_sector=2),
            (image, tensor, radius, sharpness, strength),
            eps=1e-6,
            nondet_tol=1e-12,
            atol=1e-5,
            rtol=1e-3,
        )


def test_without_grad_the_same_output() -> None:
    """Under ``no_grad`` forward keeps no sums for backward, and gives the same output."""
    image = rand(1, 3, 9, 9, seed=25)
    radius = rand(1, 1, 9, 9, low=1.0, high=4.0, seed=26)
    with kernels("fused"):
        recorded = anisotropic_kuwahara(image, _tensor(image), radius, scale=1.0)
        with torch.no_grad():
            unrecorded = anisotropic_kuwahara(image, _tensor(image), radius, scale=1.0)
    assert recorded.requires_grad and not unrecorded.requires_grad
    assert torch.equal(recorded.detach(), unrecorded)


def test_backward_repeats_on_one_thread_and_within_rounding_on_two() -> None:
    image = rand(2, 3, 12, 12, seed=18)
    radius = rand(2, 1, 12, 12, low=1.0, high=5.0, seed=19)
    assert_scatters_repeat(lambda i: anisotropic_kuwahara(i, _tensor(i), radius).sum(), image)


def test_the_fused_kernel_runs_only_when_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    from wise.filters.fused import kuwahara as fused_kuwahara

    calls = []
    original = fused_kuwahara._forward
    monkeypatch.setattr(fused_kuwahara, "_forward", lambda *a: calls.append(1) or original(*a))
    image = torch.rand(1, 3, 8, 8)
    for path in ("fused", "torch"):
        with kernels(path):
            anisotropic_kuwahara(image, _tensor(image), 2.0, scale=1.0)
    assert calls == [1]


def test_tap_arrays_hold_the_layout() -> None:
    from wise.filters.fused.kuwahara import tap_arrays

    taps = _sample_layout(8, 3)
    positions, index, weight = tap_arrays(taps)
    assert positions.shape == index.shape == weight.shape == (24, 2)
    for t, tap in enumerate(taps):
        assert tuple(positions[t]) == (tap.along, tap.across)
        assert dict(tap.sector_weights) == {int(n): float(w) for n, w in zip(index[t], weight[t]) if w > 0.0}
