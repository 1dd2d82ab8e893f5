"""The post-processing CNNs of image-to-image translation: shapes, ranges, dropout."""

from __future__ import annotations

import pytest
import torch

from wise.errors import WiseError
from wise.ppn.postprocess import ResnetTranslator, UNetTranslator, create_post


@pytest.mark.parametrize("name", ["resnet", "unet"])
@pytest.mark.parametrize("size", [(64, 64), (45, 70)])
def test_post_networks_keep_the_size_and_give_images_in_the_unit_range(name: str, size: tuple[int, int]) -> None:
    torch.manual_seed(0)
    network = create_post(name, width=4)
    image = torch.rand(2, 3, *size)
    made = network(image)
    assert made.shape == image.shape
    assert float(made.detach().min()) >= 0.0 and float(made.detach().max()) <= 1.0
    assert float(made.detach().std()) > 0.0, "an untrained network still depends on its input"
    made.mean().backward()
    assert all(p.grad is not None for p in network.parameters() if p.requires_grad)


def test_the_resnet_has_johnsons_layout() -> None:
    network = ResnetTranslator(width=8, blocks=9)
    convolutions = [m for m in network.modules() if isinstance(m, torch.nn.Conv2d)]
    # 7x7 in, two halving, two per residual block, 7x7 out
    assert len(convolutions) == 1 + 2 + 2 * 9 + 1
    assert convolutions[0].kernel_size == (7, 7) and convolutions[-1].kernel_size == (7, 7)
    widest = max(m.out_channels for m in convolutions)
    assert widest == 4 * 8


def test_the_unet_halves_depth_times_and_drops_out_only_in_training() -> None:
    torch.manual_seed(0)
    network = UNetTranslator(width=4, depth=8, dropout=True)
    halving = [m for m in network.modules() if isinstance(m, torch.nn.Conv2d) and m.stride == (2, 2)]
    assert len(halving) == 8
    assert sum(isinstance(m, torch.nn.Dropout) for m in network.modules()) == 3, "pix2pix: three noisy levels"
    image = torch.rand(1, 3, 256, 256)
    network.train()
    assert not torch.equal(network(image), network(image)), "dropout is noise while training"
    network.eval()
    assert torch.equal(network(image), network(image))
    plain = UNetTranslator(width=4, depth=8)
    assert not any(isinstance(m, torch.nn.Dropout) for m in plain.modules())


def test_unknown_or_impossible_networks_are_refused() -> None:
    with pytest.raises(WiseError, match="unknown post-processing network 'vgg'"):
        create_post("vgg")
    with pytest.raises(WiseError, match="2 to 9 levels"):
        UNetTranslator(depth=12)
