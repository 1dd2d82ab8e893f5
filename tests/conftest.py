import pytest
import torch
import torch.nn.functional as F
from skimage import data


@pytest.fixture(scope="session")
def astronaut() -> torch.Tensor:
    """``skimage.data.astronaut()`` as a (1, 3, 512, 512) float tensor in [0, 1]."""
    return torch.from_numpy(data.astronaut()).permute(2, 0, 1)[None].float() / 255.0


@pytest.fixture(scope="session")
def astronaut_small(astronaut: torch.Tensor) -> torch.Tensor:
    """The astronaut at 128x128."""
    return F.interpolate(astronaut, size=(128, 128), mode="area")
