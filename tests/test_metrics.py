import pytest
import torch

from wise import metrics


def test_far_colour_share_counts_the_pixels_of_another_colour() -> None:
    reference = torch.zeros(1, 3, 40, 40)
    reference[:, 0] = 0.6  # dark red
    image = reference.clone()
    image[:, :, :10, :] = torch.tensor([0.1, 0.2, 0.8]).view(1, 3, 1, 1)  # a quarter royal blue
    assert metrics.far_colour_share(image, reference) == pytest.approx(0.25, abs=0.03)  # + the blurred edge
    near = reference + 0.03  # a slightly lighter red is the same colour
    assert metrics.far_colour_share(near, reference) == 0.0
    with pytest.raises(ValueError, match="differ in size"):
        metrics.far_colour_share(image[..., :20], reference)


def _sky() -> torch.Tensor:
    """A smooth blue gradient, 64 x 64."""
    ramp = torch.linspace(0.5, 0.8, 64)[None, None, :, None].expand(1, 1, 64, 64)
    return torch.cat((ramp * 0.8, ramp * 0.9, ramp), dim=1).clone()


def _dashed(picture: torch.Tensor, value: float) -> torch.Tensor:
    marked = picture.clone()
    marked[..., 20, 10:30] = value  # a dash one pixel thin, 20 long
    marked[..., 40:60, 45] = value
    return marked


def test_marks_count_thin_structures_the_reference_lacks() -> None:
    sky = _sky()
    assert metrics.marks(sky, sky) == (0.0, 0.0)
    darker, lighter = metrics.marks(_dashed(sky, 0.1), sky)
    assert 30 / 4096 <= darker <= 40 / 4096 and lighter == 0.0  # the 40 pixels of the dashes, give or take
    darker, lighter = metrics.marks(_dashed(sky, 1.0), sky)
    assert darker == 0.0 and 30 / 4096 <= lighter <= 40 / 4096


def test_marks_leave_lines_the_reference_has_and_ones_it_has_alone() -> None:
    sky, dashed = _sky(), _dashed(_sky(), 0.1)
    assert metrics.marks(dashed, dashed) == (0.0, 0.0)
    assert metrics.marks(sky, dashed)[0] == 0.0  # a line missing is no mark
    # a smooth change of tone is no mark either
    assert metrics.marks(sky * 0.8, sky) == (0.0, 0.0)
