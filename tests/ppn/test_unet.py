"""The local parameter prediction network (U-Net)."""

from __future__ import annotations

import pytest
import torch

from wise import effects, ppn
from wise.errors import WiseError
from wise.ppn.unet import START_BOUND, LocalPPN


@pytest.mark.parametrize("size", [(8, 8), (37, 53), (64, 96)])
def test_masks_have_the_photo_size_and_the_bounded_range(size: tuple[int, int]) -> None:
    torch.manual_seed(0)
    network = LocalPPN(5, depth=4, width=8, max_width=16)
    masks = network(torch.rand(2, 3, *size))
    assert masks.shape == (2, 5, *size)
    assert masks.abs().max() <= 0.5


def test_an_untrained_network_paints_its_start_everywhere() -> None:
    torch.manual_seed(0)
    start = effects.create("xdog").preset("portrait")
    network = LocalPPN(len(start), depth=3, width=8, start=start)
    masks = network(torch.rand(1, 3, 40, 40))
    kept_off_the_ends = start.clamp(-START_BOUND, START_BOUND)
    assert (masks - kept_off_the_ends.view(1, -1, 1, 1)).abs().max() < 0.02
    assert masks.std(dim=(2, 3)).max() > 0, "the painted masks depend on the photo"


def test_the_masks_follow_the_photo_and_carry_gradients() -> None:
    torch.manual_seed(0)
    network = LocalPPN(2, depth=3, width=8)
    photo = torch.rand(1, 3, 32, 32)
    masks = network(photo)
    masks[:, 0].mean().backward()
    assert all(p.grad is not None for p in network.parameters())
    assert not torch.equal(network(torch.rand(1, 3, 32, 32)), masks)


def test_bad_options_are_refused() -> None:
    with pytest.raises(WiseError, match="depth"):
        LocalPPN(3, depth=1)
    with pytest.raises(WiseError, match="width"):
        LocalPPN(3, width=32, max_width=16)
    with pytest.raises(WiseError, match="start values"):
        LocalPPN(3, start=torch.zeros(4))
    with pytest.raises(WiseError, match="unknown local architecture"):
        ppn.create_local("resnet", 3)
