import json
from pathlib import Path

import torch
import torch.nn.functional as F

from wise.cli import main
from wise.io import write_image


def test_recover_benchmark_writes_per_trial_rows(tmp_path: Path, astronaut: torch.Tensor, capsys) -> None:
    photos = tmp_path / "photos"
    photos.mkdir()
    write_image(F.interpolate(astronaut, size=(40, 40), mode="area"), photos / "a.png")
    write_image(F.interpolate(astronaut.flip(-1), size=(40, 48), mode="area"), photos / "b.png")
    out = tmp_path / "recover.json"
    args = ["bench", "recover", "xdog", "--images", str(photos), "--trials", "3", "--size", "32", "--iters", "3"]
    assert main([*args, "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert len(result["trials"]) == 3 and {"mean_ssim", "mean_psnr"} <= set(result)
    assert [row["image"] for row in result["trials"]] == ["a.png", "b.png", "a.png"]
    assert 0.0 < result["mean_ssim"] <= 1.0
    assert "mean SSIM" in capsys.readouterr().out


def test_recover_refuses_an_empty_folder(tmp_path: Path, capsys) -> None:
    args = ["bench", "recover", "xdog", "--images", str(tmp_path), "--json", str(tmp_path / "r.json")]
    assert main(args) == 2
    assert "no images" in capsys.readouterr().err
