"""The Ray path of ``wise apply --ray``: the same results as the local path, resumable, a bad
image reported while the others are written, and a clear error without Ray."""

from __future__ import annotations

import json
import os
import socket
import sys
import time
from pathlib import Path

import pytest
from PIL import Image

from tests.images import astronaut_png
from wise.batch import distributed
from wise.batch.distributed import MISSING_RAY, placement, require_ray, run_on_ray
from wise.batch.inputs import Job, plan
from wise.batch.look import Look, LookSpec
from wise.batch.run import FAILED, SKIPPED, JsonLog, is_complete, run_jobs
from wise.errors import WiseError

ray = pytest.importorskip("ray")
pytest.importorskip("ray.data")
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning:ray.data.context")  # Ray's own settings

LOOK = LookSpec("xdog", preset="portrait")
SIZES = ((64, 80), (80, 64), (64, 80), (72, 80))


@pytest.fixture(scope="module")
def photos(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four small photos and, in a subfolder, a corrupt JPEG."""
    root = tmp_path_factory.mktemp("photos")
    for number, (width, height) in enumerate(SIZES):
        astronaut_png(root / f"photo{number}.png", width, height)
    (root / "sub").mkdir()
    (root / "sub" / "corrupt.jpg").write_bytes(b"\xff\xd8\xff\xe0 this is no JPEG")
    return root


@pytest.fixture(scope="module")
def reference(photos: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    """The local path's results, by file name."""
    out = tmp_path_factory.mktemp("local")
    summary = run_jobs(Look(LOOK), plan([str(photos)], out), progress=False)
    assert summary.done == len(SIZES) and len(summary.failed) == 1
    return {path.name: path.read_bytes() for path in out.rglob("*.png")}


@pytest.fixture(scope="module")
def cluster():
    """A Ray instance of 2 CPUs for the module, shut down after it."""
    started = not ray.is_initialized()
    if started:
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    if started:
        ray.shutdown()


def _good(jobs: list[Job]) -> list[Job]:
    return [job for job in jobs if job.source.suffix == ".png"]


def _finished_before(jobs: list[Job], reference: dict[str, bytes]) -> None:
    """The results of ``jobs`` written as an earlier run left them (a pipeline less to start)."""
    for job in jobs:
        job.output.parent.mkdir(parents=True, exist_ok=True)
        job.output.write_bytes(reference[job.output.name])


def test_without_ray_the_error_is_one_line(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)
    with pytest.raises(WiseError) as caught:
        require_ray()
    assert str(caught.value) == MISSING_RAY and "\n" not in MISSING_RAY
    with pytest.raises(WiseError, match="needs Ray"):
        run_on_ray(LOOK, [Job(tmp_path / "a.png", tmp_path / "out" / "a.png")])


def test_a_bad_look_fails_before_ray_starts(photos: Path, tmp_path: Path) -> None:
    was_running = ray.is_initialized()
    with pytest.raises(WiseError, match="portrait-ish"):
        run_on_ray(LookSpec("xdog", preset="portrait-ish"), plan([str(photos)], tmp_path / "out"))
    assert ray.is_initialized() == was_running
    assert not (tmp_path / "out").exists()


def test_an_address_where_no_cluster_answers_fails_at_once() -> None:
    with socket.socket() as probe:  # a port that nothing listens on
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    began = time.monotonic()
    with pytest.raises(WiseError, match="no Ray cluster answers"):
        distributed._check_reachable(f"127.0.0.1:{port}")
    assert time.monotonic() - began < distributed.CONNECT_SECONDS
    distributed._check_reachable("auto")  # left to Ray


def test_placement() -> None:
    # CPU: a few threads per actor on large machines, as many actors as the cores allow
    assert placement("cpu", 0, None, 2, 2, 0) == distributed.Placement(2, 1, 0.0, "cpu")
    assert placement("cpu", 0, None, 64, 32, 0) == distributed.Placement(16, 4, 0.0, "cpu")
    assert placement("cpu", 0, 3, 12, 12, 0) == distributed.Placement(3, 4, 0.0, "cpu")
    assert placement("cpu", 0, 2, 64, 8, 0).threads == 8  # no actor larger than a node
    # GPU: one actor per share of a GPU, rendering on it; a look on cuda gets a whole one
    assert placement("cpu", 0.5, None, 16, 16, 2) == distributed.Placement(4, 1, 0.5, "cuda")
    assert placement("cuda:0", 0, None, 16, 16, 3) == distributed.Placement(3, 1, 1.0, "cuda")
    with pytest.raises(WiseError, match="no GPU"):
        placement("cuda", 0, None, 16, 16, 0)
    for bad in (-1, float("nan"), 1.5):
        with pytest.raises(WiseError, match="gpus-per-worker"):
            placement("cpu", bad, None, 16, 16, 4)


def test_same_files_as_the_local_path(
    photos: Path,
    reference: dict[str, bytes],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """``wise apply --ray``: Ray started here (2 cores) and stopped after; every result byte for
    byte the local one, the corrupt image reported by name, one log line per image."""
    from wise.cli import main

    monkeypatch.setattr(distributed, "usable_cores", lambda: 2)
    was_running = ray.is_initialized()
    out, log = tmp_path / "out", tmp_path / "log.jsonl"
    code = main(["apply", "xdog", str(photos), "-o", str(out), "--preset", "portrait", "--ray", "--log", str(log)])
    captured = capsys.readouterr()
    assert code == 1, captured.err
    assert ray.is_initialized() == was_running
    assert f"{photos / 'sub' / 'corrupt.jpg'}: " in captured.err and "4 written" in captured.out
    assert {path.name: path.read_bytes() for path in out.rglob("*.png")} == reference
    assert not list(out.rglob(".*"))  # no temporary file left
    records = [json.loads(line) for line in log.read_text().splitlines()]
    jobs = plan([str(photos)], out)
    assert sorted(record["input"] for record in records) == sorted(str(job.source) for job in jobs)
    assert sorted(record["status"] for record in records) == ["done"] * len(SIZES) + ["failed"]
    failed = next(record for record in records if record["status"] == FAILED)
    assert failed["output"] == str(out / "sub" / "corrupt.png") and failed["error"].startswith(f"{failed['input']}: ")


class _StopAfterFirst(JsonLog):
    """A log whose second line is a Ctrl-C (the first outcome is a skipped image)."""

    def __init__(self) -> None:
        super().__init__(None)
        self.lines: list[str] = []

    def write(self, outcome) -> None:
        self.lines.append(outcome.status)
        if len(self.lines) == 2:
            raise KeyboardInterrupt


def test_ctrl_c_then_the_same_command_resumes_skips_and_overwrites(
    cluster, photos: Path, reference: dict[str, bytes], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Ctrl-C leaves whole files; the same command finishes the batch, skipping what is done;
    run again it skips everything; ``overwrite`` renders again. One actor: this is about the
    files, not about parallelism (each actor's start costs seconds)."""
    monkeypatch.chdir(tmp_path)  # paths relative to this process's folder, as typed
    out = Path("out")
    jobs = plan([os.path.relpath(photos)], out)
    good = _good(jobs)
    _finished_before(good[:1], reference)  # what a run stopped earlier leaves: skipped

    log = _StopAfterFirst()
    stopped = run_on_ray(LOOK, jobs, log=log, workers=1)
    assert stopped.interrupted and not stopped.ok
    assert log.lines[0] == SKIPPED and stopped.done + len(stopped.failed) == 1
    assert stopped.remaining == len(jobs) - 2
    for path in (path for path in out.rglob("*") if path.is_file()):  # complete, nothing half written
        assert not path.name.startswith(".") and path.read_bytes() == reference[path.name]
        with Image.open(path) as image:
            image.load()

    rest = run_on_ray(LOOK, jobs, workers=1)  # the same command finishes the batch
    # skipped: the image done before, the one done before the Ctrl-C and any finished as it came
    assert rest.skipped >= 1 + stopped.done and rest.done + rest.skipped == len(SIZES) and len(rest.failed) == 1
    corrupt = os.path.relpath(photos / "sub" / "corrupt.jpg")
    assert rest.failed[0].input == corrupt and rest.failed[0].error.startswith(f"{corrupt}: ")
    assert {path.name: path.read_bytes() for path in out.rglob("*.png")} == reference
    assert all(is_complete(job) for job in good)

    (out / "photo0.png").write_bytes(b"not the result")  # what a skip would keep
    again = run_on_ray(LOOK, good, workers=1)
    assert again.skipped == len(SIZES) and again.done == 0 and again.ok
    assert (out / "photo0.png").read_bytes() == b"not the result"

    redone = run_on_ray(LOOK, good[:1], overwrite=True, workers=1)
    assert redone.done == 1 and redone.skipped == 0 and redone.ok
    assert (out / "photo0.png").read_bytes() == reference["photo0.png"]
    assert ray.is_initialized()  # a cluster it joined is left running


def test_an_image_that_kills_its_worker_fails_alone(
    cluster, photos: Path, reference: dict[str, bytes], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A worker that dies on one image (a crash, the memory monitor) is restarted and the image
    tried again, then reported as failed; the others are written."""

    class Crashing(distributed._Stylizer):
        def __call__(self, batch):
            if any(str(source).endswith("photo1.png") for source in batch["source"]):
                os._exit(1)
            return super().__call__(batch)

    monkeypatch.setattr(distributed, "_Stylizer", Crashing)
    monkeypatch.setattr(distributed, "TASK_RETRIES", 1)  # tried again once: a restart less to wait for
    out = tmp_path / "out"
    jobs = _good(plan([str(photos)], out))
    summary = run_on_ray(LOOK, jobs)
    assert [failure.input for failure in summary.failed] == [str(photos / "photo1.png")]
    assert summary.failed[0].error == f"{photos / 'photo1.png'}: {distributed.LOST}"
    assert summary.done == len(jobs) - 1 and not summary.interrupted
    assert {path.name: path.read_bytes() for path in out.rglob("*.png")} == {
        name: data for name, data in reference.items() if name != "photo1.png"
    }


def test_the_command_line_without_ray_refuses_in_one_line(
    monkeypatch: pytest.MonkeyPatch, photos: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from wise.cli import main

    monkeypatch.setitem(sys.modules, "ray", None)
    code = main(["apply", "xdog", str(photos), "-o", str(tmp_path / "out"), "--ray"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and 'pip install "wise[ray]"' in err, err
    assert not (tmp_path / "out").exists()


def test_a_write_that_ends_after_the_actors_were_stopped_leaves_no_temporary(tmp_path: Path) -> None:
    """An actor killed as the pipeline closes can still be ending its write: its temporary file,
    appearing a moment later, is removed too; a finished output is kept."""
    import threading

    job = Job(tmp_path / "photo.png", tmp_path / "out" / "photo.png", None)
    job.output.parent.mkdir()
    (job.output.parent / "other.png").write_bytes(b"finished")
    late = job.output.parent / ".photo.png.abc123.tmp"
    writer = threading.Timer(0.3, late.write_bytes, args=(b"half",))
    writer.start()
    began = time.monotonic()
    distributed._remove_temporaries([job])
    writer.join()
    assert not late.exists() and (job.output.parent / "other.png").read_bytes() == b"finished"
    assert time.monotonic() - began < distributed.LEFTOVER_SECONDS + 0.5
    began = time.monotonic()
    distributed._remove_temporaries([])  # nothing cut off: no wait
    assert time.monotonic() - began < 0.5 * distributed.LEFTOVER_SECONDS
