"""``wise data adaptive``: a small set end to end, Ctrl-C, and one-line refusals before any work."""

from __future__ import annotations

import json
import os
import re
import signal
from pathlib import Path

import pytest
from PIL import Image
from skimage import data

from wise.cli import main
from wise.train import adaptive
from wise.train.tasks import TASKS

IS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0
SMALL = ["--min-change", "0", "--count", "4", "--size", "32"]


@pytest.fixture(scope="module")
def photos(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("photos")
    for name in ("astronaut", "coffee", "chelsea"):
        Image.fromarray(getattr(data, name)()).resize((48, 40)).save(root / f"{name}.png")
    return root


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _snapshot(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_makes_a_small_set(photos: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "sets" / "pairs"
    code, stdout, err = run(["data", "adaptive", "details", "--images", str(photos), "-o", str(out), *SMALL], capsys)
    assert code == 0 and err == ""
    summary = r"3 training and 1 test pairs in .+; mean region share \d+%; 0 left out where the change did not show"
    assert re.fullmatch(summary, stdout.splitlines()[-1])
    task = json.loads((out / "task.json").read_text())
    assert task["task"] == "details" and task["count"] == 4 and task["size"] == 32
    assert len(list((out / "train" / "B").glob("*.png"))) == 3 and len(list((out / "test" / "B").glob("*.png"))) == 1


def test_ctrl_c_returns_130_with_a_usable_set(
    photos: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    calls = []
    make = adaptive.make_pair

    def interrupted_on_the_second(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202 (stands in for make_pair)
        calls.append(1)
        if len(calls) == 2:
            signal.raise_signal(signal.SIGINT)
        return make(*args, **kwargs)

    monkeypatch.setattr(adaptive, "make_pair", interrupted_on_the_second)
    out = tmp_path / "pairs"
    code, stdout, err = run(["data", "adaptive", "contours", "--images", str(photos), "-o", str(out), *SMALL], capsys)
    assert code == 130 and err.splitlines() == ["wise: interrupted"]
    assert "interrupted: 1 of 4 pairs written" in stdout
    assert json.loads((out / "task.json").read_text())["count"] == 1
    assert len(list(out.glob("*/A/*.png"))) == len(list(out.glob("*/params/*.safetensors"))) == 1


def _refusals(photos: Path, tmp: Path) -> dict[str, tuple[list[str], str]]:
    """Each case: its arguments and a fragment of the message."""
    empty, lonely, a_file = tmp / "empty", tmp / "lonely", tmp / "a-file"
    empty.mkdir()
    (empty / "notes.png").write_text("not an image")
    lonely.mkdir()
    (lonely / "one.png").write_bytes((photos / "coffee.png").read_bytes())
    a_file.write_text("a file")
    held = tmp / "held"
    (held / "train").mkdir(parents=True)
    out = str(tmp / "out")
    base = ["data", "adaptive"]

    def args(task: str = "details", images: Path | str = photos, output: str = out, *extra: str) -> list[str]:
        return [*base, task, "--images", str(images), "-o", output, *SMALL, *extra]

    return {
        "unknown task": (args("edges"), "invalid choice: 'edges'"),
        "unknown effect": (args("details", photos, out, "--effect", "pencil"), "unknown effect 'pencil'"),
        "unsupported effect": (
            args("background", photos, out, "--effect", "watercolor"),
            "no parameter for the effect 'watercolor'; supported effects: cartoon, xdog",
        ),
        "unknown preset": (args("details", photos, out, "--preset", "bold"), "has no preset 'bold'"),
        "missing folder": (args("details", tmp / "missing"), "not a directory of photos"),
        "folder is a file": (args("details", a_file), "not a directory of photos"),
        "no readable photos": (args("details", empty), "0 readable photos"),
        "one photo": (args("details", lonely), "1 readable photos"),
        "photos too small": (args("details", photos, out, "--size", "64"), "0 readable photos of at least 64"),
        "count 1": (args("details", photos, out, "--count", "1"), "--count: must be from 2"),
        "count not a number": (args("details", photos, out, "--count", "many"), "'many' is not a whole number"),
        "size too small": (args("details", photos, out, "--size", "8"), "--size: must be from 16"),
        "share 0": (args("details", photos, out, "--test-share", "0"), "--test-share: must be above 0"),
        "share 1": (args("details", photos, out, "--test-share", "1"), "--test-share: must be below 1"),
        "share nan": (args("details", photos, out, "--test-share", "nan"), "not a finite number"),
        "negative seed": (args("details", photos, out, "--seed", "-1"), "--seed: must be from 0"),
        "output is a file": (args("details", photos, str(a_file)), "exists and is not a directory"),
        "output is the photo folder": (args("details", photos, str(photos)), "inside the photo folder"),
        "output inside the photo folder": (args("details", photos, str(photos / "pairs")), "inside the photo folder"),
        "output holds the photo folder": (args("details", photos, str(photos.parent)), "holds the photo folder"),
        "output holds pairs": (args("details", photos, str(held)), "holds pairs already (train)"),
    }


CASES = (
    "unknown task", "unknown effect", "unsupported effect", "unknown preset", "missing folder", "folder is a file",
    "no readable photos", "one photo", "photos too small", "count 1", "count not a number", "size too small",
    "share 0", "share 1", "share nan", "negative seed", "output is a file", "output is the photo folder",
    "output inside the photo folder", "output holds the photo folder", "output holds pairs",
)  # fmt: skip


@pytest.mark.parametrize("case", CASES)
def test_bad_input_is_refused_before_any_work(
    case: str, photos: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv, message = _refusals(photos, tmp_path)[case]
    before, photos_before = _snapshot(tmp_path), _snapshot(photos)
    code, stdout, err = run(argv, capsys)
    assert code == 2 and stdout == ""
    assert len(err.splitlines()) == 1 and err.startswith("wise: error: ") and message in err, err
    assert _snapshot(tmp_path) == before and _snapshot(photos) == photos_before
    assert not (tmp_path / "out").exists()


@pytest.mark.skipif(IS_ROOT, reason="root writes into read-only folders")
def test_unwritable_output_is_refused(photos: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        code, stdout, err = run(
            ["data", "adaptive", "details", "--images", str(photos), "-o", str(locked / "pairs"), *SMALL], capsys
        )
    finally:
        locked.chmod(0o700)
    assert code == 2 and stdout == "" and "cannot write into the directory" in err and len(err.splitlines()) == 1
    assert not (locked / "pairs").exists()


def test_help_names_the_tasks(capsys: pytest.CaptureFixture[str]) -> None:
    code, text, _ = run(["data", "adaptive", "--help"], capsys)
    assert code == 0
    assert all(task in text for task in TASKS) and "--test-share" in text
