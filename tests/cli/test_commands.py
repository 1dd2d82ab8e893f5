"""The ``wise`` command: listing, applying, and one-line refusals with exit code 2."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

import wise
from tests.images import astronaut_png
from wise.cli import main
from wise.effects.base import Effect
from wise.io import read_image
from wise.paramfile import save_params
from wise.params import ParamSpec

SRC = Path(wise.__file__).resolve().parent.parent


class Toon(Effect):
    """An effect that is not xdog, for a params file made for another effect."""

    name = "toon"
    param_specs = (ParamSpec("levels", 2.0, 16.0, 8.0),)

    def render(self, image: torch.Tensor, p: dict[str, torch.Tensor]) -> torch.Tensor:
        return image


@pytest.fixture(scope="module")
def photo(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return astronaut_png(tmp_path_factory.mktemp("img") / "photo.png", 64, 48)


@pytest.fixture(scope="module")
def xdog() -> Effect:
    return wise.effects.create("xdog")


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_effects_lists_xdog(capsys: pytest.CaptureFixture[str], xdog: Effect) -> None:
    code, out, err = run(["effects"], capsys)
    assert code == 0 and err == ""
    assert "xdog" in out
    for spec in xdog.param_specs:
        assert spec.name in out and spec.description in out
    assert "portrait" in out and "sketch" in out
    outside = any(not xdog.spec(k).in_range(v) for preset in xdog.presets.values() for k, v in preset.items())
    assert ("outside the declared range; rendered as authored" in out) == outside
    code, single, _ = run(["effects", "xdog"], capsys)
    assert code == 0 and single.strip() in out
    for name in wise.effects.available():
        assert f"{name}: " in out


def test_effects_marks_values_outside_range(capsys: pytest.CaptureFixture[str], xdog: Effect) -> None:
    out = run(["effects", "xdog"], capsys)[1]
    for name, preset in xdog.presets.items():
        line = next(row for row in out.splitlines() if row.strip().startswith(name + " "))
        for key, value in preset.items():
            marked = f"{key}={value:.6g}*" in line
            assert marked == (not xdog.spec(key).in_range(value)), line


def test_apply_preset_set_and_kernel_size(tmp_path: Path, photo: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out1 = tmp_path / "preset.png"
    argv = ["apply", "xdog", str(photo), "-o", str(out1), "--preset", "sketch", "--device", "cpu"]
    code, printed, _ = run(argv, capsys)
    assert code == 0
    assert printed.startswith(f"wrote {out1} (64x48, ") and printed.endswith(" s)\n") and printed.count("\n") == 1
    out2 = tmp_path / "set.jpg"
    argv = [
        "apply",
        "xdog",
        str(photo),
        "-o",
        str(out2),
        "--set",
        "blackness=0.4",
        "--set",
        "contour=2",
        "--kernel-size",
        "2",
        "--quiet",
    ]
    assert run(argv, capsys) == (0, "", "")
    a, b = read_image(out1), read_image(out2)
    assert a.shape == b.shape == (1, 3, 48, 64)
    assert not torch.equal(a, read_image(photo))


def test_apply_params_files(tmp_path: Path, photo: Path, xdog: Effect, capsys: pytest.CaptureFixture[str]) -> None:
    save_params(tmp_path / "global.safetensors", xdog, xdog.preset("portrait"))
    from_file = tmp_path / "file.png"
    assert (
        run(
            ["apply", "xdog", str(photo), "-o", str(from_file), "--params", str(tmp_path / "global.safetensors")],
            capsys,
        )[0]
        == 0
    )
    from_preset = tmp_path / "preset.png"
    assert run(["apply", "xdog", str(photo), "-o", str(from_preset), "--preset", "portrait"], capsys)[0] == 0
    assert torch.equal(read_image(from_file), read_image(from_preset))

    masks = xdog.preset("portrait")[:, None, None].repeat(1, 4, 4).clone()
    masks[xdog.param_names.index("contour"), :2] = 0.4
    save_params(tmp_path / "local.safetensors", xdog, masks, space="real")
    local = tmp_path / "local.png"
    argv = [
        "apply",
        "xdog",
        str(photo),
        "-o",
        str(local),
        "--params",
        str(tmp_path / "local.safetensors"),
        "--set",
        "contour=1",
    ]
    assert run(argv, capsys)[0] == 0
    assert float((read_image(local) - read_image(from_preset)).abs().max()) < 1e-2


def check_refusal(code: int, err: str, output: Path) -> None:
    assert code == 2
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("wise: error: ")
    assert "Traceback" not in err
    assert not output.exists()
    if output.parent.is_dir():
        assert not list(output.parent.glob(".*.tmp"))


def refusal_cases(tmp: Path, photo: Path) -> dict[str, tuple[list[str], Path, str]]:
    """Named argv lists that must be refused, with their output path and a word of the message."""
    out = tmp / "out.png"
    text = tmp / "notes.png"
    text.write_text("not an image")
    save_params(tmp / "toon.safetensors", Toon(), torch.zeros(1))
    base = ["apply", "xdog", str(photo), "-o", str(out)]
    return {
        "unknown effect": (["apply", "oil", str(photo), "-o", str(out)], out, "unknown effect 'oil'"),
        "unknown parameter": (base + ["--set", "sharpness=1"], out, "no parameter 'sharpness'"),
        "unknown preset": (base + ["--preset", "noir"], out, "no preset 'noir'"),
        "out of range": (base + ["--set", "contour=99"], out, "outside the range [0, 3]"),
        "non-image input": (["apply", "xdog", str(text), "-o", str(out)], out, "not an image"),
        "missing input": (["apply", "xdog", str(tmp / "nope.png"), "-o", str(out)], out, "no such file"),
        "unwritable output": (
            ["apply", "xdog", str(photo), "-o", str(tmp / "no-dir" / "out.png")],
            tmp / "no-dir" / "out.png",
            "does not exist",
        ),
        "other effect params": (base + ["--params", str(tmp / "toon.safetensors")], out, "'toon'"),
    }


EXTRA_CASES = {
    "malformed set": (["--set", "contour"], "expected NAME=VALUE"),
    "non-numeric set": (["--set", "contour=lots"], "not a number"),
    "nan set": (["--set", "contour=nan"], "finite"),
    "params and preset": (["--preset", "sketch", "--params", "x.safetensors"], "cannot be combined"),
    "bad kernel size": (["--kernel-size", "0"], "--kernel-size: must be from 1"),
    "non-integer kernel size": (["--kernel-size", "two"], "not a whole number"),
    "bad quality": (["--quality", "101"], "quality"),
}


@pytest.mark.parametrize(
    "case",
    [
        "unknown effect",
        "unknown parameter",
        "unknown preset",
        "out of range",
        "non-image input",
        "missing input",
        "unwritable output",
        "other effect params",
    ],
)
def test_refusals_in_process(case: str, tmp_path: Path, photo: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv, output, words = refusal_cases(tmp_path, photo)[case]
    code, out, err = run(argv, capsys)
    check_refusal(code, err, output)
    assert words in err


@pytest.mark.parametrize("case", sorted(EXTRA_CASES))
def test_more_refusals(case: str, tmp_path: Path, photo: Path, capsys: pytest.CaptureFixture[str]) -> None:
    extra, words = EXTRA_CASES[case]
    output = tmp_path / "out.png"
    code, _, err = run(["apply", "xdog", str(photo), "-o", str(output), *extra], capsys)
    check_refusal(code, err, output)
    assert words in err


def test_refusals_of_listing_and_outputs(tmp_path: Path, photo: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(["effects", "oil"], capsys)
    assert code == 2 and out == "" and err.startswith("wise: error: unknown effect 'oil'")
    output = tmp_path / "out.webp"
    check_refusal(*run(["apply", "xdog", str(photo), "-o", str(output)], capsys)[::2], output)
    (tmp_path / "file").write_text("")
    output = tmp_path / "file" / "out.png"
    check_refusal(*run(["apply", "xdog", str(photo), "-o", str(output)], capsys)[::2], output)
    assert run([], capsys)[0] == 2
    assert run(["--help"], capsys)[0] == 0


@pytest.mark.skipif(torch.cuda.is_available(), reason="CUDA is available")
def test_cuda_without_cuda_is_refused(tmp_path: Path, photo: Path, capsys: pytest.CaptureFixture[str]) -> None:
    output = tmp_path / "out.png"
    code, _, err = run(["apply", "xdog", str(photo), "-o", str(output), "--device", "cuda"], capsys)
    check_refusal(code, err, output)
    assert "CUDA is not available" in err


def test_refusals_as_subprocess(tmp_path: Path, photo: Path) -> None:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(SRC), os.environ.get("PYTHONPATH")]))}
    cases = refusal_cases(tmp_path, photo)
    # all at once: each refusal is an interpreter's start, and the cases share nothing
    processes = {
        case: subprocess.Popen(
            [sys.executable, "-m", "wise", *argv],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
            cwd=tmp_path,
        )  # fmt: skip
        for case, (argv, _, _) in cases.items()
    }
    for case, (_, output, words) in cases.items():
        stdout, stderr = processes[case].communicate(timeout=120)
        assert stdout == "", case
        check_refusal(processes[case].returncode, stderr, output)
        assert words in stderr, (case, stderr)


def test_module_entry_point_lists_effects(tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    proc = subprocess.run(
        [sys.executable, "-m", "wise", "effects", "xdog"], capture_output=True, text=True, env=env, timeout=120
    )
    assert proc.returncode == 0 and "stroke_width" in proc.stdout and proc.stderr == ""


def test_gallery_writes_a_labelled_sheet(tmp_path: Path, photo: Path, capsys: pytest.CaptureFixture[str]) -> None:
    sheet = tmp_path / "sheet.png"
    code, out, err = run(
        ["gallery", str(photo), "-o", str(sheet), "--size", "48", "--effects", "xdog", "cartoon"], capsys
    )
    assert code == 0 and err == ""
    assert "xdog" in out and "cartoon" in out
    image = read_image(sheet)
    assert image.shape[-1] > 2 * 48 and image.shape[-2] > 3 * 48  # original row + two effect rows


def test_gallery_refuses_unknown_effects(tmp_path: Path, photo: Path, capsys: pytest.CaptureFixture[str]) -> None:
    sheet = tmp_path / "sheet.png"
    code, _, err = run(["gallery", str(photo), "-o", str(sheet), "--effects", "nope"], capsys)
    check_refusal(code, err, sheet)
