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


def test_the_demos_closing_hints_run_as_printed_in_a_new_shell(tmp_path, monkeypatch) -> None:
    """After `make demo`, `wise` is not on a new shell's PATH: the hints name the script itself."""
    import os
    import shlex
    import subprocess
    import sys
    from pathlib import Path

    monkeypatch.chdir(tmp_path)
    out = Path("out")
    demo.run(out)
    venv_bin = str(Path(sys.executable).parent)
    path = os.pathsep.join(p for p in os.environ.get("PATH", "").split(os.pathsep) if p != venv_bin)
    monkeypatch.setenv("PATH", path)
    apply_hint = next(line for line in demo.hints(out, out / "transfer" / "report.html") if " apply " in line)
    command = apply_hint.split(": ", 1)[1]
    done = subprocess.run(["bash", "-c", command], env={**os.environ, "PATH": path}, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "out" / "edited.png").exists()
    assert shlex.split(command)[0] != "wise"  # the venv's script, since `wise` is not on this PATH
