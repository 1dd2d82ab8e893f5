"""Ctrl-C: every long command stops within a few seconds with exit code 130, and what it has
written is complete (real processes, real SIGINT)."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from PIL import Image
from skimage import data

import wise
from wise.interrupt import ctrl_c
from wise.io import read_image
from wise.optimize.settings import RESULT_FILES
from wise.paramfile import load_params

SRC = Path(wise.__file__).resolve().parent.parent
STOP_WITHIN = 10.0
"""Seconds from SIGINT to exit, writing the results included (CI machines are slow)."""


def _start(argv: list[str], cwd: Path) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(SRC), os.environ.get("PYTHONPATH")]))
    return subprocess.Popen(
        [sys.executable, "-m", "wise", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=cwd,
    )


def _wait_for(proc: subprocess.Popen[str], words: str, timeout: float = 120.0) -> list[str]:
    """Lines of stdout up to the first one containing ``words``."""
    assert proc.stdout is not None
    deadline, lines = time.monotonic() + timeout, []
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            raise AssertionError(f"exited ({proc.wait()}) before {words!r}: {lines} {proc.stderr.read()}")
        lines.append(line)
        if words in line:
            return lines
    raise AssertionError(f"no {words!r} within {timeout} s")


def _interrupt(proc: subprocess.Popen[str]) -> tuple[int, float, str]:
    """SIGINT; the exit code and seconds to exit. stderr must be the one line saying so."""
    start = time.monotonic()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert err.splitlines() == ["wise: interrupted"], err
    return proc.returncode, time.monotonic() - start, err


@pytest.fixture(scope="module")
def photos(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("photos")
    Image.fromarray(data.astronaut()).resize((96, 96)).save(folder / "photo.png")
    Image.fromarray(data.coffee()).resize((96, 96)).save(folder / "target.png")
    return folder


def test_optimize_keeps_complete_resumable_results(photos: Path, tmp_path: Path) -> None:
    run = tmp_path / "run"
    argv = ["optimize", "xdog", "--content", str(photos / "photo.png"), "--target", str(photos / "target.png")]
    proc = _start([*argv, "-o", str(run), "--size", "64", "--iters", "100000", "--levels", "1"], tmp_path)
    _wait_for(proc, "iteration 20/")
    proc.send_signal(signal.SIGINT)
    _wait_for(proc, "interrupted after")
    code, seconds, err = _interrupt(proc)  # a second Ctrl-C while the results are written
    assert code == 130 and seconds < STOP_WITHIN, (code, seconds, err)
    assert "Traceback" not in err
    assert sorted(p.name for p in run.iterdir()) == sorted(RESULT_FILES)
    scores = json.loads((run / "metrics.json").read_text())
    assert scores["interrupted"] is True and scores["iterations"] >= 20
    effect = wise.effects.create("xdog")
    assert load_params(run / "params.safetensors", effect).shape[:2] == (1, len(effect.param_specs))
    assert read_image(run / "result.png").shape[-2:] == (96, 96)
    assert (run / "report.html").read_text().rstrip().endswith("</html>")


def test_bench_recover_writes_the_finished_trials(photos: Path, tmp_path: Path) -> None:
    folder = tmp_path / "photos"
    folder.mkdir()
    (folder / "a.png").write_bytes((photos / "photo.png").read_bytes())
    out = tmp_path / "bench.json"
    argv = ["bench", "recover", "xdog", "--images", str(folder), "--json", str(out), "--size", "32"]
    proc = _start([*argv, "--trials", "50", "--iters", "20"], tmp_path)
    _wait_for(proc, "| 0 |")
    code, seconds, err = _interrupt(proc)
    assert code == 130 and seconds < STOP_WITHIN, (code, seconds, err)
    result = json.loads(out.read_text())
    assert result["interrupted"] is True
    assert result["trials_finished"] == len(result["trials"]) >= 1
    assert [row["trial"] for row in result["trials"]] == list(range(len(result["trials"])))
    assert result["mean_ssim"] is not None


def test_apply_leaves_no_partial_file(photos: Path, tmp_path: Path) -> None:
    big = tmp_path / "big.png"
    Image.fromarray(data.astronaut()).resize((3072, 3072)).save(big)
    out = tmp_path / "out.png"
    proc = _start(["apply", "oilpaint", str(big), "-o", str(out), "--device", "cpu"], tmp_path)
    time.sleep(6.0)
    assert proc.poll() is None, "the render finished before the interruption"
    code, seconds, err = _interrupt(proc)
    assert code == 130 and seconds < STOP_WITHIN, (code, seconds, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.png"]


def test_transfer_interrupted_while_optimizing_keeps_every_file(photos: Path, tmp_path: Path) -> None:
    run = tmp_path / "run"
    argv = ["transfer", "watercolor", "--content", str(photos / "photo.png"), "--builtin-style", "0"]
    proc = _start([*argv, "-o", str(run), "--size", "64", "--iters", "100000", "--levels", "1"], tmp_path)
    _wait_for(proc, "iteration 10/")
    code, seconds, err = _interrupt(proc)
    assert code == 130 and seconds < STOP_WITHIN, (code, seconds, err)
    assert sorted(p.name for p in run.iterdir()) == sorted((*RESULT_FILES, "target.png"))


def test_edit_stops_with_130(photos: Path, tmp_path: Path) -> None:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    proc = _start(["edit", str(photos / "photo.png"), "--port", str(port)], tmp_path)
    _wait_for(proc, "http://")
    code, seconds, err = _interrupt(proc)
    assert code == 130 and seconds < STOP_WITHIN, (code, seconds, err)
    assert "Traceback" not in err


def test_first_ctrl_c_stops_later_ones_are_held() -> None:
    with ctrl_c() as interruption:
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)
        finished = False
        os.kill(os.getpid(), signal.SIGINT)  # the second one, while "writing"
        time.sleep(0.05)
        finished = True
    assert finished and interruption.received
    with ctrl_c() as held:
        held.hold()
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.05)
    assert held.received
    with ctrl_c() as quiet:
        pass
    assert not quiet.received
    with pytest.raises(KeyboardInterrupt):  # the previous handler is back
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(1.0)
