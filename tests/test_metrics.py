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
