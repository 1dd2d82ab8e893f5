import torch

import wise
from wise import demo
from wise.cli import main as wise_main
from wise.io import read_image


def test_demo_writes_both_presets_and_their_params(tmp_path) -> None:
    written = demo.run(tmp_path)
    names = sorted(p.name for p in written)
    presets = wise.effects.create("xdog").presets
    assert names == sorted(["astronaut.png"] + [f"xdog_{p}.{ext}" for p in presets for ext in ("png", "safetensors")])
    rerendered = tmp_path / "again.png"
    args = ["apply", "xdog", str(tmp_path / "astronaut.png"), "--params", str(tmp_path / "xdog_sketch.safetensors")]
    assert wise_main(args + ["-o", str(rerendered)]) == 0
    assert torch.equal(read_image(rerendered), read_image(tmp_path / "xdog_sketch.png"))


def test_demo_transfer_writes_a_report(tmp_path, monkeypatch) -> None:
    demo.run(tmp_path)
    monkeypatch.setattr(demo, "DEMO_ITERATIONS", 2)
    monkeypatch.setattr(demo, "DEMO_SIZE", 32)
    report = demo.transfer_demo(tmp_path)
    assert report.exists() and "watercolor" in report.read_text()
