"""``wise``, ``wise --help``, ``wise effects`` and the refusals of bad arguments and inputs answer
before PyTorch loads (its import alone takes seconds): each case runs in a fresh interpreter that
reports whether ``torch`` was imported."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

PROGRAM = """
import sys
from wise.cli import main
code = main(sys.argv[1:])
print("torch loaded" if "torch" in sys.modules else "torch not loaded", file=sys.stderr)
sys.exit(code)
"""


def _cases(folder: Path) -> dict[str, tuple[list[str], int, str]]:
    """Each case: the arguments, the exit code and a piece of what it prints."""
    photo, empty = folder / "photo.png", folder / "empty.png"
    out = str(folder / "out.png")
    missing = str(folder / "missing.png")
    return {
        "no command": ([], 2, "required: COMMAND"),
        "help": (["--help"], 0, "list effects, their parameters and presets"),
        "a command's help": (["apply", "--help"], 0, "--preset NAME"),
        "effects": (["effects"], 0, "watercolor:"),
        "one effect": (["effects", "oilpaint"], 0, "stroke_length"),
        "missing file": (["apply", "xdog", missing, "-o", out], 2, "no such file"),
        "a directory for an image": (
            ["optimize", "xdog", "--content", str(folder), "--target", str(photo), "-o", str(folder / "o")],
            2,
            "is a directory",
        ),  # fmt: skip
        "an empty file": (["apply", "cartoon", str(empty), "-o", out], 2, "the file is empty"),
        "unknown effect": (["apply", "oil", str(photo), "-o", out], 2, "unknown effect 'oil'"),
        "unknown preset": (["apply", "xdog", "--preset", "pen", str(photo), "-o", out], 2, "no preset 'pen'"),
        "unknown parameter": (["apply", "xdog", "--set", "width=1", str(photo), "-o", out], 2, "no parameter 'width'"),
        "value out of range": (["apply", "xdog", "--set", "details=9", str(photo), "-o", out], 2, "outside the range"),
        "not a number": (["apply", "xdog", "--set", "details=much", str(photo), "-o", out], 2, "is not a number"),
        "bad option value": (["apply", "xdog", "--kernel-size", "0", str(photo), "-o", out], 2, "--kernel-size"),
        "unwritable output": (
            ["apply", "xdog", str(photo), "-o", str(folder / "no" / "such" / "out.png")],
            2,
            "wise: error:",
        ),  # fmt: skip
        "output format": (["apply", "xdog", str(photo), "-o", str(folder / "out.gif")], 2, ".gif"),
        "options that exclude each other": (
            ["apply", "xdog", "--preset", "sketch", "--params", str(photo), str(photo), "-o", out],
            2,
            "cannot be combined",
        ),  # fmt: skip
        "transfer's start": (
            [
                "transfer",
                "xdog",
                "--content",
                str(photo),
                "--builtin-style",
                "1",
                "--init",
                "pen",
                "-o",
                str(folder / "t"),
            ],
            2,
            "no preset 'pen'",
        ),  # fmt: skip
        "predict's example": (
            ["predict", "cartoon", "--content", str(photo), "--target", missing, "-o", str(folder / "p")],
            2,
            "no such file",
        ),  # fmt: skip
        "the editor's start": (["edit", "--preset", "sketch"], 2, "--preset needs --effect"),
        "train's kind": (["train", "regional"], 2, "invalid choice: 'regional'"),
        "train's effect": (
            ["train", "global", "oil", "--images", str(folder), "-o", str(folder / "r")],
            2,
            "unknown effect 'oil'",
        ),
        "train's architecture": (
            ["train", "global", "xdog", "--images", str(folder), "--arch", "vgg", "-o", str(folder / "r")],
            2,
            "'vgg'",
        ),
        "train's pairs": (
            ["train", "local", "xdog", "--pairs", missing, "-o", str(folder / "r")],
            2,
            "not a directory of pairs",
        ),  # fmt: skip
        "data's task": (["data", "adaptive", "edges", "--images", str(folder), "-o", str(folder / "p")], 2, "'edges'"),
        "data's photos": (["data", "drawing", "--images", missing, "-o", str(folder / "p")], 2, "not a directory"),
        "bench's photos": (
            ["bench", "recover", "xdog", "--images", missing, "--json", str(folder / "r.json")],
            2,
            "not a directory of images",
        ),  # fmt: skip
        "bench's start": (
            ["bench", "recover", "xdog", "--images", str(folder), "--init", "nn", "--json", str(folder / "r.json")],
            2,
            "--init 'nn'",
        ),  # fmt: skip
        "bench's metrics": (
            [
                "bench",
                "pairs",
                "--model",
                "builtin:contours",
                "--pairs",
                str(folder),
                "--json",
                str(folder / "r.json"),
                "--inception-weights",
                str(photo),
            ],
            2,
            "add --fid",
        ),  # fmt: skip
    }


CASES = list(_cases(Path("/nonexistent")))


@pytest.mark.parametrize("case", CASES)
def test_answers_before_pytorch_loads(case: str, tmp_path: Path) -> None:
    (tmp_path / "photo.png").write_bytes(b"\x89PNG not really")
    (tmp_path / "empty.png").touch()
    argv, code, expected = _cases(tmp_path)[case]
    done = subprocess.run([sys.executable, "-c", PROGRAM, *argv], capture_output=True, text=True, timeout=60)
    assert done.returncode == code, done.stderr
    assert expected in done.stdout + done.stderr
    lines = done.stderr.strip().splitlines()
    assert lines[-1] == "torch not loaded", done.stderr
    if code == 2:
        assert len(lines) == 2 and lines[0].startswith("wise: error: ")  # one line, no traceback
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty.png", "photo.png"]  # nothing written
