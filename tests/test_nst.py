import pytest
import torch
import torch.nn.functional as F

from wise.errors import WiseError
from wise.nst import builtin_style_count, stylize


@pytest.fixture(scope="module")
def photo(astronaut: torch.Tensor) -> torch.Tensor:
    return F.interpolate(astronaut, size=(96, 80), mode="area")


def test_builtin_styles_restyle_the_photo(photo: torch.Tensor) -> None:
    assert builtin_style_count() == 26
    first, second = stylize(photo, builtin_style=3), stylize(photo, builtin_style=19)
    assert first.shape == photo.shape and second.shape == photo.shape
    assert (first - photo).abs().mean() > 0.05 and (first - second).abs().mean() > 0.02


def test_any_image_serves_as_style(photo: torch.Tensor) -> None:
    stripes = torch.zeros(1, 3, 64, 64)
    stripes[:, 0, :, ::8] = 1.0
    result = stylize(photo, style=stripes)
    assert result.shape == photo.shape and (result - photo).abs().mean() > 0.02


def test_bad_style_requests(photo: torch.Tensor) -> None:
    with pytest.raises(WiseError, match="from 0 to 25"):
        stylize(photo, builtin_style=26)
    with pytest.raises(WiseError, match="either"):
        stylize(photo)
