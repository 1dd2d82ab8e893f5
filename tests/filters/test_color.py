import pytest
import torch

from wise import filters as W
from wise.errors import WiseError


def _pixel(r: float, g: float, b: float) -> torch.Tensor:
    return torch.tensor([r, g, b], dtype=torch.float64).view(1, 3, 1, 1)


@pytest.mark.parametrize(
    ("rgb", "lab"),
    [
        ((1.0, 1.0, 1.0), (100.0, 0.0, 0.0)),
        ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
        ((1.0, 0.0, 0.0), (53.24, 80.09, 67.20)),
        ((0.0, 0.0, 1.0), (32.30, 79.19, -107.86)),
    ],
)
def test_lab_known_values(rgb, lab) -> None:
    result = W.rgb_to_lab(_pixel(*rgb)).flatten()
    assert torch.allclose(result, torch.tensor(lab, dtype=torch.float64), atol=0.05)


def test_lab_round_trip(astronaut_small: torch.Tensor) -> None:
    back = W.lab_to_rgb(W.rgb_to_lab(astronaut_small))
    assert (back - astronaut_small).abs().max() < 1e-4


def test_hsv_round_trip(astronaut_small: torch.Tensor) -> None:
    back = W.hsv_to_rgb(W.rgb_to_hsv(astronaut_small))
    assert (back - astronaut_small).abs().max() < 1e-5


def test_adjust_color_identity(astronaut_small: torch.Tensor) -> None:
    assert torch.allclose(W.adjust_color(astronaut_small), astronaut_small, atol=1e-6)


def test_zero_saturation_is_hsv_value(astronaut_small: torch.Tensor) -> None:
    grey = W.adjust_color(astronaut_small, saturation=0.0)
    value = astronaut_small.max(dim=1, keepdim=True).values
    assert torch.allclose(grey, value.expand_as(grey), atol=1e-6)


def test_saturation_keeps_hue_and_value(astronaut_small: torch.Tensor) -> None:
    before = W.rgb_to_hsv(astronaut_small)
    after = W.rgb_to_hsv(W.adjust_color(astronaut_small, saturation=0.5))
    coloured = before[:, 1] > 0.1
    assert torch.allclose(after[:, 2], before[:, 2], atol=1e-5)
    assert torch.allclose(after[:, 1][coloured], 0.5 * before[:, 1][coloured], atol=1e-4)
    hue_error = (after[:, 0] - before[:, 0]).abs()
    assert torch.minimum(hue_error, 1 - hue_error)[coloured].max() < 1e-4


def test_hue_shift_rotates_hue(astronaut_small: torch.Tensor) -> None:
    before = W.rgb_to_hsv(astronaut_small)
    after = W.rgb_to_hsv(W.adjust_color(astronaut_small, hue_shift=0.25))
    coloured = before[:, 1] > 0.2
    shift = torch.remainder(after[:, 0] - before[:, 0], 1.0)[coloured]
    assert (shift - 0.25).abs().max() < 1e-3


def test_brightness_contrast_gamma() -> None:
    mid = torch.full((1, 3, 2, 2), 0.5)
    assert torch.allclose(W.adjust_color(mid, contrast=3.0), mid)
    assert torch.allclose(W.adjust_color(mid, brightness=0.2), mid + 0.2)
    assert torch.allclose(W.adjust_color(mid, gamma=2.0), mid.sqrt())
    assert torch.allclose(W.adjust_color(mid, exposure=1.5), mid * 1.5)


def test_per_pixel_parameter_map(astronaut_small: torch.Tensor) -> None:
    contrast = torch.ones(1, 1, 128, 128)
    contrast[..., :64] = 2.0
    out = W.adjust_color(astronaut_small, contrast=contrast)
    assert torch.allclose(out[..., 64:], astronaut_small[..., 64:], atol=1e-6)
    assert torch.allclose(out[..., :64], W.adjust_color(astronaut_small, contrast=2.0)[..., :64], atol=1e-6)


def test_bad_shapes_are_refused(astronaut_small: torch.Tensor) -> None:
    with pytest.raises(WiseError, match="3 channel"):
        W.rgb_to_lab(astronaut_small[:, :2])
    with pytest.raises(WiseError, match="contrast"):
        W.adjust_color(astronaut_small, contrast=torch.ones(1, 1, 5, 5))


def test_white_balance_offsets_are_orthogonal_and_keep_grey_grey() -> None:
    mid = torch.full((1, 3, 1, 1), 0.5, dtype=torch.float64)
    warm = W.adjust_color(mid, temperature=0.2).flatten()
    magenta = W.adjust_color(mid, tint=0.2).flatten()
    assert torch.allclose(warm, torch.tensor([0.6, 0.5, 0.4], dtype=torch.float64))
    assert torch.allclose(magenta, torch.tensor([0.6, 0.3, 0.6], dtype=torch.float64))
    assert abs(float(((warm - 0.5) * (magenta - 0.5)).sum())) < 1e-12
    assert float((warm - 0.5).sum()) == pytest.approx(0.0) and float((magenta - 0.5).sum()) == pytest.approx(0.0)


def test_brightness_temperature_and_tint_masks_reach_any_colour() -> None:
    grey = torch.full((1, 3, 1, 1), 0.5, dtype=torch.float64)
    wanted = torch.tensor([0.2, 0.7, 0.9], dtype=torch.float64)
    offset = wanted - 0.5
    brightness = offset.mean()
    temperature = offset[0] - offset[2]
    tint = (offset[0] + offset[2]) / 2 - offset[1]
    tint = 2.0 * tint / 3.0
    out = W.adjust_color(grey, brightness=float(brightness), temperature=float(temperature), tint=float(tint))
    assert torch.allclose(out.flatten(), wanted, atol=1e-9)
