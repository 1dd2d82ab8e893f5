"""``wise apply`` over folders, patterns and many inputs: results equal to single renders,
faults reported by name, resumption, models, parameter files, Ctrl-C."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from skimage import data

import wise
from wise.batch import stylize
from wise.cli import main

SRC = Path(wise.__file__).resolve().parent.parent


def _pixels(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"))


@pytest.fixture(scope="module")
def tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``photos/`` with a subfolder, a corrupt JPEG, a text file and a hidden file."""
    root = tmp_path_factory.mktemp("many")
    photos = root / "photos"
    (photos / "cats" / "older").mkdir(parents=True)
    Image.fromarray(data.astronaut()).resize((160, 160)).save(photos / "astronaut.png")
    Image.fromarray(data.coffee()).resize((180, 120)).save(photos / "coffee.jpg", quality=90)
    Image.fromarray(data.chelsea()).resize((150, 100)).save(photos / "cats" / "chelsea.png")
    Image.fromarray(data.chelsea()[::-1]).resize((120, 90)).save(photos / "cats" / "older" / "flipped.webp")
    whole = (photos / "coffee.jpg").read_bytes()
    (photos / "cats" / "broken.jpg").write_bytes(whole[:200])
    (photos / "notes.txt").write_text("not an image")
    (photos / ".hidden.png").write_text("not an image either")
    return root


READABLE = ("astronaut.png", "coffee.png", "cats/chelsea.png", "cats/older/flipped.png")


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _times(folder: Path) -> dict[str, int]:
    return {str(p.relative_to(folder)): p.stat().st_mtime_ns for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_folder_tree_renders_each_image_as_alone_and_resumes(tree: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tree / "out"
    argv = ["apply", "xdog", str(tree / "photos"), "-o", str(out), "--preset", "portrait"]
    code, stdout, stderr = _run(argv, capsys)
    assert code == 1, stderr
    assert sorted(_times(out)) == sorted(READABLE)
    assert "broken.jpg" in stderr and stderr.count("failed:") == 1, stderr
    assert "4 written" in stdout and "1 failed" in stdout, stdout
    for name, source in zip(READABLE, ("astronaut.png", "coffee.jpg", "cats/chelsea.png", "cats/older/flipped.webp")):
        alone = tree / f"alone-{Path(name).name}"
        assert main(["apply", "xdog", str(tree / "photos" / source), "-o", str(alone), "--preset", "portrait"]) == 0
        assert np.array_equal(_pixels(out / name), _pixels(alone)), name

    before = _times(out)
    code, stdout, stderr = _run(argv, capsys)
    assert code == 1 and "broken.jpg" in stderr and stderr.count("failed:") == 1, stderr
    assert "0 written, 4 skipped" in stdout, stdout
    assert _times(out) == before, "nothing is rendered again"

    code, stdout, _ = _run([*argv, "--overwrite"], capsys)
    assert code == 1 and "4 written" in stdout
    after = _times(out)
    assert all(after[name] != before[name] for name in READABLE)


def test_patterns_several_inputs_jpeg_results_and_the_log(tree: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out, log = tree / "out-jpg", tree / "run.jsonl"
    pattern = str(tree / "photos" / "**" / "*.png")
    argv = ["apply", "xdog", pattern, str(tree / "photos" / "coffee.jpg"), "-o", str(out), "--format", "jpg",
            "--log", str(log), "--workers", "3"]  # fmt: skip
    code, stdout, stderr = _run(argv, capsys)
    assert code == 0, stderr
    assert sorted(_times(out)) == ["astronaut.jpg", "cats/chelsea.jpg", "coffee.jpg"]
    records = [json.loads(line) for line in log.read_text().splitlines()]
    assert sorted(Path(r["output"]).name for r in records) == ["astronaut.jpg", "chelsea.jpg", "coffee.jpg"]
    assert {r["status"] for r in records} == {"done"} and all(r["error"] is None for r in records)
    assert all(set(r) == {"input", "output", "status", "seconds", "error"} for r in records)


def test_the_python_api_returns_a_summary(tree: Path) -> None:
    summary = stylize(tree / "photos" / "cats", tree / "api", "cartoon", preset="bold", workers=1)
    assert (summary.done, summary.skipped, len(summary.failed)) == (2, 0, 1)
    assert "broken.jpg" in summary.failed[0].error
    assert (tree / "api" / "older" / "flipped.png").is_file()


def test_a_local_model_paints_each_image_as_predict_does(tree: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tree / "painted"
    argv = ["apply", "xdog", str(tree / "photos" / "cats"), str(tree / "photos" / "astronaut.png"), "-o", str(out),
            "--model", "builtin:contours", "--save-params"]  # fmt: skip
    code, _, stderr = _run(argv, capsys)
    assert code == 1 and "broken.jpg" in stderr
    predicted = tree / "predicted"
    code = main(["predict", "xdog", "--content", str(tree / "photos" / "cats" / "chelsea.png"), "-o", str(predicted),
                 "--model", "builtin:contours"])  # fmt: skip
    assert code == 0
    ours = _pixels(out / "chelsea.png").astype(float)
    theirs = _pixels(predicted / "result.png").astype(float)
    assert np.abs(ours - theirs).mean() <= 1.0, "equal to wise predict within 1/255"
    again = tree / "again.png"
    assert main(["apply", "xdog", str(tree / "photos" / "cats" / "chelsea.png"), "-o", str(again),
                 "--params", str(out / "chelsea.safetensors")]) == 0  # fmt: skip
    assert np.abs(_pixels(again).astype(float) - ours).mean() <= 1.0, "the saved masks reproduce the result"
    assert (out / "astronaut.safetensors").is_file() and (out / "older" / "flipped.safetensors").is_file()


def _start(argv: list[str]) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(SRC), os.environ.get("PYTHONPATH")]))
    return subprocess.Popen([sys.executable, "-m", "wise", *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)  # fmt: skip


def test_ctrl_c_leaves_complete_files_and_the_same_command_finishes(tmp_path: Path) -> None:
    photos = tmp_path / "twelve"
    photos.mkdir()
    picture = Image.fromarray(data.astronaut()).resize((384, 384))
    for i in range(12):
        picture.rotate(i * 7).save(photos / f"{i:02d}.png")
    out = tmp_path / "out"
    argv = ["apply", "watercolor", str(photos), "-o", str(out)]
    proc = _start(argv)
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline and len(list(out.glob("*.png"))) < 3:
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.05)
    start = time.monotonic()
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=60)
    seconds = time.monotonic() - start
    assert proc.returncode == 130, stderr
    assert seconds < 5.0, f"took {seconds:.1f} s to stop"
    assert "Traceback" not in stderr
    written = sorted(p.name for p in out.iterdir())
    assert 3 <= len(written) < 12, written
    for name in written:
        assert name.endswith(".png") and not name.startswith("."), written
        Image.open(out / name).load()
    finished = subprocess.run([sys.executable, "-m", "wise", *argv], capture_output=True, text=True,
                              env={**os.environ, "PYTHONPATH": str(SRC)}, timeout=600)  # fmt: skip
    assert finished.returncode == 0, finished.stderr
    assert f"{12 - len(written)} written, {len(written)} skipped" in finished.stdout
    assert len(list(out.glob("*.png"))) == 12


def test_images_above_the_pixel_limit_fail_by_name_and_the_rest_render(
    tree: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tree / "limited"
    code, stdout, stderr = _run(
        ["apply", "xdog", str(tree / "photos"), "-o", str(out), "--max-pixels", "20000"], capsys
    )
    assert code == 1
    assert "astronaut.png" in stderr and "coffee.jpg" in stderr and "broken.jpg" in stderr, stderr
    assert sorted(_times(out)) == ["cats/chelsea.png", "cats/older/flipped.png"]
    assert "2 written" in stdout and "3 failed" in stdout
