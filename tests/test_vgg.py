import os
from pathlib import Path

import pytest
import torch
from safetensors.torch import save_file

import wise.files
import wise.nst
from tests.weights import sparse_weights
from wise.cli import main
from wise.errors import WiseError
from wise.io import write_image
from wise.vgg import StyleLoss, VGG19Features, expected_shapes, load_vgg19, weights_file


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


def test_transfer_by_gatys_with_user_weights(
    weights: Path, tmp_path: Path, capsys, monkeypatch, brief_readings: None
) -> None:
    monkeypatch.setattr(wise.nst, "GATYS_STEPS", 2)  # the command's path, not the users' 200 steps
    content, style = tmp_path / "c.png", tmp_path / "s.png"
    write_image(torch.rand(1, 3, 32, 40), content)
    write_image(torch.rand(1, 3, 24, 24), style)
    out = tmp_path / "t"
    base = ["transfer", "cartoon", "--content", str(content), "--style", str(style), "--nst", "gatys"]
    assert main([*base, "-o", str(out), "--iters", "1", "--size", "32", "--vgg-weights", str(weights)]) == 0
    assert (out / "target.png").exists()
    assert main([*base, "-o", str(tmp_path / "n"), "--vgg-weights", str(tmp_path / "none.safetensors")]) == 2
    assert "VGG-19 weights not found" in capsys.readouterr().err and not (tmp_path / "n").exists()


@pytest.fixture
def no_data_reads(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(data: bytes) -> dict[str, torch.Tensor]:
        raise AssertionError("tensor data was read")

    monkeypatch.setattr(wise.files, "_st_load", refuse)


def test_the_header_check_refuses_wrong_files_without_loading(tmp_path: Path, no_data_reads: None) -> None:
    shapes = expected_shapes()
    assert weights_file(sparse_weights(tmp_path / "ok.safetensors", shapes)) == tmp_path / "ok.safetensors"
    wrong = sparse_weights(tmp_path / "wrong.safetensors", {**shapes, "features.0.weight": (64, 3, 5, 5)})
    with pytest.raises(WiseError) as info:
        weights_file(wrong)
    message = str(info.value)
    assert "features.0.weight is [64, 3, 5, 5], expected [64, 3, 3, 3]" in message and "--vgg-weights" in message
    partial = {k: v for k, v in shapes.items() if not k.startswith("features.34")}
    with pytest.raises(WiseError, match=r"not a VGG-19 state dict; missing features\.34\.weight, features\.34\.bias;"):
        weights_file(sparse_weights(tmp_path / "partial.safetensors", partial))
    with pytest.raises(WiseError, match="floating point"):
        weights_file(sparse_weights(tmp_path / "int.safetensors", shapes, dtype="I32"))
    with pytest.raises(WiseError, match="not a safetensors file"):
        (tmp_path / "text.safetensors").write_text("weights")
        weights_file(tmp_path / "text.safetensors")
    with pytest.raises(WiseError, match="character device"):
        os.symlink("/dev/zero", tmp_path / "zero.safetensors")
        weights_file(tmp_path / "zero.safetensors")


def test_only_the_features_are_read(tmp_path: Path, weights: Path) -> None:
    state = {k: v.contiguous() for k, v in VGG19Features().state_dict().items()}
    path = tmp_path / "full.safetensors"
    save_file({**state, "classifier.0.bias": torch.zeros(4096)}, str(path))
    model = load_vgg19(path)
    assert torch.equal(model.features[0].weight, state["features.0.weight"])


def test_a_wrong_weights_file_fails_before_any_work(tmp_path: Path, capsys) -> None:
    content = tmp_path / "c.png"
    write_image(torch.rand(1, 3, 32, 32), content)
    wrong = sparse_weights(tmp_path / "wrong.safetensors", {"features.0.weight": (64, 3, 3, 3)})
    out = tmp_path / "o"
    args = ["optimize", "xdog", "--content", str(content), "--target", str(content), "-o", str(out), "--loss", "nst"]
    assert main([*args, "--vgg-weights", str(wrong)]) == 2
    assert "not a VGG-19 state dict" in capsys.readouterr().err and not out.exists()
