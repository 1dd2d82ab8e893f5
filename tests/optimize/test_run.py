import json
from pathlib import Path

import pytest
import torch
import torch.nn.functional as F

import wise
from wise.cli import main
from wise.io import read_image, write_image


@pytest.fixture(scope="module")
def images(tmp_path_factory: pytest.TempPathFactory, astronaut: torch.Tensor) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp("optimize")
    content = F.interpolate(astronaut, size=(48, 64), mode="area")
    effect = wise.effects.create("cartoon")
    with torch.no_grad():
        target = effect(content, effect.preset("bold")[None])
    write_image(content, folder / "content.png")
    write_image(target, folder / "target.png")
    return folder / "content.png", folder / "target.png"


def optimize_args(images: tuple[Path, Path], out: Path, *extra: str) -> list[str]:
    content, target = images
    return ["optimize", "cartoon", "--content", str(content), "--target", str(target), "-o", str(out), *extra]


def test_optimize_writes_every_output_and_apply_reproduces_the_result(images, tmp_path: Path, brief_readings) -> None:
    out = tmp_path / "run"
    assert main(optimize_args(images, out, "--iters", "6", "--size", "48")) == 0
    assert {p.name for p in out.iterdir()} >= {
        "result.png",
        "params.safetensors",
        "metrics.json",
        "report.html",
        "optimization.gif",
    }
    scores = json.loads((out / "metrics.json").read_text())
    assert {"l1", "psnr", "ssim", "seconds", "iterations", "effect", "mode"} <= set(scores)
    assert scores["iterations"] == 6 and scores["effect"] == "cartoon" and scores["mode"] == "local"
    assert [level["reduction"] for level in scores["levels"]] == [4, 2, 1]
    assert sum(level["iterations"] for level in scores["levels"]) == 6
    again = tmp_path / "again.png"
    content = images[0]
    assert main(["apply", "cartoon", str(content), "--params", str(out / "params.safetensors"), "-o", str(again)]) == 0
    assert torch.equal(read_image(again), read_image(out / "result.png"))


def test_an_interrupted_run_writes_a_state_that_resumes(images, tmp_path: Path, monkeypatch, brief_readings) -> None:
    import wise.optimize.run as run_module

    calls = {"n": 0}
    real = run_module.tensor_to_image

    def interrupt_on_third_frame(tensor: torch.Tensor):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return real(tensor)

    monkeypatch.setattr(run_module, "tensor_to_image", interrupt_on_third_frame)
    first = tmp_path / "first"
    assert main(optimize_args(images, first, "--iters", "40", "--size", "48")) == 130
    scores = json.loads((first / "metrics.json").read_text())
    assert scores["interrupted"] is True and scores["iterations"] < 40
    monkeypatch.setattr(run_module, "tensor_to_image", real)
    second = tmp_path / "second"
    resume = ["--iters", "3", "--size", "48", "--init", str(first / "params.safetensors")]
    assert main(optimize_args(images, second, *resume)) == 0
    assert json.loads((second / "metrics.json").read_text())["iterations"] == 3


def test_a_target_of_another_aspect_is_refused(images, tmp_path: Path, capsys) -> None:
    other = tmp_path / "square.png"
    write_image(torch.rand(1, 3, 40, 40), other)
    out = tmp_path / "refused"
    args = ["optimize", "cartoon", "--content", str(images[0]), "--target", str(other), "-o", str(out), "--iters", "2"]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "aspect ratio" in err[0]
    assert not out.exists()


def test_a_target_of_another_size_is_resized(images, tmp_path: Path, capsys, brief_readings) -> None:
    bigger = tmp_path / "bigger.png"
    write_image(F.interpolate(read_image(images[1]), size=(96, 128), mode="bilinear"), bigger)
    args = ["optimize", "cartoon", "--content", str(images[0]), "--target", str(bigger), "-o", str(tmp_path / "o")]
    assert main([*args, "--iters", "2", "--size", "48"]) == 0
    assert "resizing the target" in capsys.readouterr().out


def test_transfer_makes_the_reference_then_optimizes(images, tmp_path: Path) -> None:
    out = tmp_path / "transfer"
    args = ["transfer", "watercolor", "--content", str(images[0]), "--builtin-style", "7", "-o", str(out)]
    assert main([*args, "--iters", "2", "--size", "32"]) == 0
    assert (out / "target.png").exists() and (out / "report.html").exists()
    assert read_image(out / "target.png").shape == read_image(images[0]).shape


def test_progress_names_the_level_its_size_and_the_time_left() -> None:
    from wise.optimize.parametric import Settings, pyramid
    from wise.optimize.run import Progress

    levels = pyramid(Settings(iterations=30))
    progress = Progress(levels)
    first_count = levels[0][1].iterations
    early = progress.line(first_count, 0.05, torch.zeros(1, 3, 16, 20))
    assert early.startswith(f"iteration {first_count}/30  level 1/{len(levels)} (20x16)  loss 0.05000  about ")
    assert early.endswith(" s left")
    assert progress.line(30, 0.01, torch.zeros(1, 3, 64, 80)).endswith(
        f"level {len(levels)}/{len(levels)} (80x64)  loss 0.01000  about 0 s left"
    )


def test_optimize_reads_the_number_of_levels_off_the_target_first(images, tmp_path: Path, capsys) -> None:
    out = tmp_path / "read"
    assert main(optimize_args(images, out, "--iters", "1", "--size", "48", "--mode", "global")) == 0
    said = capsys.readouterr().out
    line = next(line for line in said.splitlines() if line.startswith("read off the target: "))
    assert "bins 4." in line  # the bold preset's 4 levels
    assert said.index("reading the look's steps off the target") < said.index(line)  # nothing waits silently
    params = json.loads((out / "metrics.json").read_text()).get("params")
    assert params is None or params["bins"] == pytest.approx(4.0, abs=0.5)


def test_of_two_starts_the_first_level_decides_and_says_so(off_the_staircase) -> None:
    import io

    from wise.optimize.parametric import Settings
    from wise.optimize.run import _first_level_decides

    case = off_the_staircase
    first_level = (2, Settings(mode="local", iterations=2, lr=1e-4, loss="l1", held=("bins",)))
    for starts in ([case.wrong, case.truth], [case.truth, case.wrong]):
        said = io.StringIO()
        chosen = _first_level_decides(case.cartoon, case.content, case.target, starts, first_level, said)
        assert chosen is case.truth
        assert "the first level (2 iterations at 32 px) runs from each" in said.getvalue()
        assert "going on from" in said.getvalue()
    said = io.StringIO()
    assert _first_level_decides(case.cartoon, case.content, case.target, [case.wrong], first_level, said) is case.wrong
    assert said.getvalue() == ""


def test_a_start_that_descent_strayed_from_is_kept_and_said(off_the_staircase) -> None:
    import io

    from wise.optimize.parametric import Outcome
    from wise.optimize.run import _kept_start

    case = off_the_staircase
    strayed = Outcome(params=case.wrong.clone(), result=case.cartoon(case.content, case.wrong).detach())
    said = io.StringIO()
    kept = _kept_start(case.cartoon, case.content, case.target, case.truth, strayed, "l1", said)
    assert torch.equal(kept.params, case.truth) and torch.equal(kept.result, case.target)
    assert "keeping the start" in said.getvalue()
    better = Outcome(params=case.truth.clone(), result=case.target)
    said = io.StringIO()
    assert _kept_start(case.cartoon, case.content, case.target, case.wrong, better, "l1", said) is better
    assert said.getvalue() == ""


def test_the_time_left_counts_from_the_start_of_descent_not_the_reading() -> None:
    from wise.optimize.parametric import Settings, pyramid
    from wise.optimize.run import Progress

    levels = pyramid(Settings(iterations=30))
    progress = Progress(levels)
    progress.began -= 1000.0  # a long reading of the steps before descent
    progress.start()
    line = progress.line(levels[0][1].iterations, 0.05, torch.zeros(1, 3, 16, 20))
    assert float(line.split("about ")[1].split(" s left")[0]) < 5.0


def test_masks_start_from_the_outlines_and_ramps_as_given_where_the_reading_inks_more_or_steps_harder(
    images, monkeypatch: pytest.MonkeyPatch
) -> None:
    import io

    import wise.optimize.run as run_module

    content, target = (read_image(path) for path in images)
    cartoon = wise.effects.create("cartoon")
    given = cartoon.default_params().reshape(1, -1)
    inky = cartoon.params_from_dict({"bins": 4.0, "softness": 0.0, "contour": 3.0, "blackness": 0.5}).reshape(1, -1)
    monkeypatch.setattr(run_module, "read_starts", lambda *args, **kwargs: ([inky], ("bins",)))
    said = io.StringIO()
    starts, _, _ = run_module._read_steps(cartoon, content, target, given, "local", said)
    assert cartoon.params_to_dict(starts[0][0]) == pytest.approx({**cartoon.params_to_dict(given[0]), "bins": 4.0})
    assert "descent cannot take ink away or move a plateau" in said.getvalue()
    said = io.StringIO()
    starts, _, _ = run_module._read_steps(cartoon, content, target, given, "global", said)
    assert torch.equal(starts[0], inky)  # one value for the whole picture has its gradient at the edges
    assert "ink" not in said.getvalue()
