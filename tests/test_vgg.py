from pathlib import Path

import pytest
import torch
from safetensors.torch import save_file

from wise.cli import main
from wise.errors import WiseError
from wise.io import write_image
from wise.vgg import StyleLoss, VGG19Features, load_vgg19


@pytest.fixture(scope="module")
def weights(tmp_path_factory: pytest.TempPathFactory) -> Path:
    torch.manual_seed(0)
    path = tmp_path_factory.mktemp("vgg") / "vgg19.safetensors"
    save_file({k: v.contiguous() for k, v in VGG19Features().state_dict().items()}, str(path))
    return path


def test_weights_load_and_the_style_loss_prefers_the_style(weights: Path) -> None:
    vgg = load_vgg19(weights)
    torch.manual_seed(1)
    content = torch.rand(1, 3, 32, 32)
    style = torch.zeros(1, 3, 32, 32)
    style[:, 0, :, ::4] = 1.0
    loss = StyleLoss(vgg, content, style)
    assert float(loss(content)) > 0
    image = content.clone().requires_grad_()
    loss(image).backward()
    assert torch.isfinite(image.grad).all() and image.grad.abs().sum() > 0


def test_missing_or_unsafe_weights_are_refused(tmp_path: Path) -> None:
    with pytest.raises(WiseError, match="VGG-19 weights not found"):
        load_vgg19(tmp_path / "none.safetensors")
    pickle = tmp_path / "vgg19.pth"
    pickle.write_bytes(b"not loaded")
    with pytest.raises(WiseError, match="safetensors"):
        load_vgg19(pickle)
    wrong = tmp_path / "wrong.safetensors"
    save_file({"features.0.weight": torch.zeros(1)}, str(wrong))
    with pytest.raises(WiseError, match="not a VGG-19 state dict"):
        load_vgg19(wrong)


def test_optimize_with_the_nst_loss(weights: Path, tmp_path: Path, capsys) -> None:
    content, target = tmp_path / "c.png", tmp_path / "t.png"
    write_image(torch.rand(1, 3, 32, 32), content)
    write_image(torch.rand(1, 3, 32, 32), target)
    args = ["optimize", "xdog", "--content", str(content), "--target", str(target), "-o", str(tmp_path / "o")]
    assert main([*args, "--iters", "2", "--size", "32", "--loss", "nst", "--vgg-weights", str(weights)]) == 0
    refused = [*args[:-1], str(tmp_path / "refused"), "--loss", "nst", "--vgg-weights", str(tmp_path / "x.safetensors")]
    assert main(refused) == 2
    assert "VGG-19 weights not found" in capsys.readouterr().err
    assert not (tmp_path / "refused").exists()


def test_transfer_by_gatys_with_user_weights(weights: Path, tmp_path: Path, capsys) -> None:
    content, style = tmp_path / "c.png", tmp_path / "s.png"
    write_image(torch.rand(1, 3, 32, 40), content)
    write_image(torch.rand(1, 3, 24, 24), style)
    out = tmp_path / "t"
    base = ["transfer", "cartoon", "--content", str(content), "--style", str(style), "--nst", "gatys"]
    assert main([*base, "-o", str(out), "--iters", "1", "--size", "32", "--vgg-weights", str(weights)]) == 0
    assert (out / "target.png").exists()
    assert main([*base, "-o", str(tmp_path / "n"), "--vgg-weights", str(tmp_path / "none.safetensors")]) == 2
    assert "VGG-19 weights not found" in capsys.readouterr().err and not (tmp_path / "n").exists()
