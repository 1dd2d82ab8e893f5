"""The global parameter prediction networks: shapes, range, gradients, ImageNet weights."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import torch
from safetensors.torch import save_file
from torch import nn

from wise.errors import WiseError
from wise.filters.quantize import quantize
from wise.ppn import ARCHITECTURES, create
from wise.ppn.resnet import ResNetPPN
from wise.ppn.tone import COMB_COUNTS, CURVE_POINTS, TONE_FEATURES, comb_scores, tone_features
from wise.ppn.weights import fold_batchnorm, load_resnet50, load_vgg11

PARAMS = 7


@pytest.mark.parametrize("architecture", sorted(ARCHITECTURES))
@pytest.mark.parametrize("size", [(64, 64), (48, 80)])
def test_predictions_are_normalized_parameters(architecture: str, size: tuple[int, int]) -> None:
    torch.manual_seed(0)
    network = create(architecture, PARAMS)
    photo = torch.rand(2, 3, *size, requires_grad=True)
    example = torch.rand(2, 3, *size)
    predicted = network(photo, example)
    assert predicted.shape == (2, PARAMS)
    assert float(predicted.detach().abs().max()) <= 0.5
    predicted.sum().backward()
    assert photo.grad is not None and float(photo.grad.abs().sum()) > 0
    assert not torch.equal(predicted[0], predicted[1])  # the images matter


def test_unknown_architecture_is_refused() -> None:
    with pytest.raises(WiseError, match="unknown architecture 'vit'"):
        create("vit", PARAMS)


def test_folded_batchnorm_equals_conv_then_batchnorm() -> None:
    torch.manual_seed(0)
    conv, bn = nn.Conv2d(3, 5, 3, padding=1, bias=False), nn.BatchNorm2d(5).eval()
    bn.running_mean.uniform_(-1, 1)
    bn.running_var.uniform_(0.5, 2)
    bn.weight.data.uniform_(0.5, 1.5)
    bn.bias.data.uniform_(-1, 1)
    folded = nn.Conv2d(3, 5, 3, padding=1)
    fold_batchnorm(folded, conv.weight.detach(), {k: v.detach() for k, v in bn.state_dict().items()})
    x = torch.rand(1, 3, 8, 8)
    assert torch.allclose(folded(x), bn(conv(x)), atol=1e-5)


def _torchvision_resnet50_state(model: ResNetPPN) -> dict[str, torch.Tensor]:
    """Random weights in torchvision's resnet50 layout (convolutions without bias, BatchNorms)."""
    generator = torch.Generator().manual_seed(1)
    state = {}
    for name, module in model.named_modules():
        if not isinstance(module, nn.Conv2d) or name.startswith("heads"):
            continue
        in_channels = 3 if name == "conv1" else module.in_channels
        conv_key = name.replace("downsample", "downsample.0")
        bn_key = name.replace("downsample", "downsample.1") if "downsample" in name else name.replace("conv", "bn")
        state[f"{conv_key}.weight"] = 0.05 * torch.randn(
            module.out_channels, in_channels, *module.kernel_size, generator=generator
        )
        channels = module.out_channels
        state[f"{bn_key}.weight"] = 1 + 0.1 * torch.randn(channels, generator=generator)
        state[f"{bn_key}.bias"] = 0.1 * torch.randn(channels, generator=generator)
        state[f"{bn_key}.running_mean"] = 0.1 * torch.randn(channels, generator=generator)
        state[f"{bn_key}.running_var"] = 1 + 0.1 * torch.rand(channels, generator=generator)
        state[f"{bn_key}.num_batches_tracked"] = torch.tensor(1)
    state["fc.weight"] = torch.zeros(1000, 2048)
    return state


def test_resnet50_weights_load_folded(tmp_path: Path) -> None:
    model = ResNetPPN(PARAMS)
    state = _torchvision_resnet50_state(model)
    path = tmp_path / "resnet50.safetensors"
    save_file(state, path)
    load_resnet50(model, path)
    scale = state["bn1.weight"] / torch.sqrt(state["bn1.running_var"] + 1e-5)
    expected = state["conv1.weight"].repeat(1, 2, 1, 1) / 2 * scale.view(-1, 1, 1, 1)
    assert torch.allclose(model.conv1.weight, expected)
    down = state["layer2.0.downsample.1.weight"] / torch.sqrt(state["layer2.0.downsample.1.running_var"] + 1e-5)
    assert torch.allclose(
        model.layer2[0].downsample.weight, state["layer2.0.downsample.0.weight"] * down.view(-1, 1, 1, 1)
    )

    del state["layer3.2.conv2.weight"]
    save_file(state, tmp_path / "incomplete.safetensors")
    with pytest.raises(WiseError, match="layer3.2.conv2.weight is missing"):
        load_resnet50(ResNetPPN(PARAMS), tmp_path / "incomplete.safetensors")


def test_vgg11_weights_load_and_bad_files_are_refused(tmp_path: Path) -> None:
    torch.manual_seed(0)
    source, target = create("multifeature", PARAMS), create("multifeature", PARAMS)
    path = tmp_path / "vgg11.safetensors"
    save_file({f"features.{k}": v for k, v in source.features.state_dict().items()}, path)
    load_vgg11(target, path)
    image = torch.rand(1, 3, 64, 64)
    assert torch.equal(source.features(image), target.features(image))

    wrong = {f"features.{k}": v for k, v in source.features.state_dict().items()}
    wrong["features.0.weight"] = torch.zeros(64, 1, 3, 3)
    save_file(wrong, tmp_path / "wrong.safetensors")
    with pytest.raises(WiseError, match="features.0.weight has the shape"):
        load_vgg11(target, tmp_path / "wrong.safetensors")
    (tmp_path / "vgg11.pth").write_bytes(b"pickle")
    with pytest.raises(WiseError, match="pickled .pth files are not loaded"):
        load_vgg11(target, tmp_path / "vgg11.pth")
    os.mkfifo(tmp_path / "fifo.safetensors")
    with pytest.raises(WiseError, match="not a regular file"):
        load_vgg11(target, tmp_path / "fifo.safetensors")


def test_statsnet_predicts_the_same_for_a_window_of_a_texture_as_for_the_whole() -> None:
    torch.manual_seed(0)
    network = create("stats", PARAMS)
    cell = torch.rand(1, 3, 16, 16)
    whole, example = cell.repeat(1, 1, 8, 8), (1.0 - cell).repeat(1, 1, 8, 8)
    with torch.no_grad():
        on_whole = network(whole, example)
        on_window = network(whole[..., :64, :64], example[..., :64, :64])
        other = network(torch.rand(1, 3, 64, 64), example[..., :64, :64])
    # the same up to the borders of the window (zero padding), unlike another picture
    assert float((on_whole - on_window).abs().max()) < 0.3 * float((on_whole - other).abs().max())


def test_tone_features_read_the_tone_curve_and_the_level_count() -> None:
    generator = torch.Generator().manual_seed(0)
    photo = torch.rand(1, 3, 64, 64, generator=generator)
    brighter = tone_features(photo, (photo + 0.2).clamp(0.0, 1.0))
    darker = tone_features(photo, (photo - 0.2).clamp(0.0, 1.0))
    lightness = slice(0, CURVE_POINTS)  # the example's L* against the photo's
    assert bool((brighter[0, lightness] > darker[0, lightness]).all())
    ramp = torch.rand(1, 1, 1, 4096, generator=generator)
    for count in (3.0, 7.0, 12.5):
        levels = quantize(ramp, torch.tensor([count]), torch.tensor([0.0])).reshape(1, -1)
        scores = comb_scores(levels)[0, : len(COMB_COUNTS)]
        assert COMB_COUNTS[int(scores.argmax())] == count
        assert float(scores.max()) > 0.99


def test_tonenet_learns_from_the_tone_features_too() -> None:
    torch.manual_seed(0)
    network = create("tone", PARAMS)
    photo = torch.rand(2, 3, 32, 32)
    with torch.no_grad():
        before = network(photo, photo)
        network.head[0].weight[:, -TONE_FEATURES:] += 0.5  # only the weights that read the tone features
        after = network(photo, photo)
    assert float((after - before).abs().max()) > 1e-3


def test_the_light_names_are_the_registries() -> None:
    """The commands check names against wise.ppn.choices before PyTorch loads; those names must
    be the networks that load."""
    from wise.ppn import LOCAL_ARCHITECTURES
    from wise.ppn.choices import ARCHITECTURE_NAMES, LOCAL_ARCHITECTURE_NAMES, POST_NETWORK_NAMES, POST_WIDTH
    from wise.ppn.postprocess import DEFAULT_WIDTH, POST_NETWORKS

    assert tuple(ARCHITECTURES) == ARCHITECTURE_NAMES
    assert tuple(LOCAL_ARCHITECTURES) == LOCAL_ARCHITECTURE_NAMES
    assert tuple(POST_NETWORKS) == POST_NETWORK_NAMES and DEFAULT_WIDTH == POST_WIDTH
