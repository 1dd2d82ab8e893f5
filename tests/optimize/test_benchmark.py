import json
from pathlib import Path

import pytest
import torch
import torch.nn.functional as F

from wise import effects
from wise.cli import main
from wise.io import write_image
from wise.optimize.benchmark import schedule
from wise.optimize.parametric import closest
from wise.optimize.trials import MIN_REFERENCE_CONTRAST, PSNR_CAP, random_reference


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
    assert result["levels"][-1] == {"reduction": 1, "iterations": 1, "lr": 0.1 * 0.3, "crop": 128}
    assert "mean SSIM" in capsys.readouterr().out


def test_recover_refuses_an_empty_folder(tmp_path: Path, capsys) -> None:
    args = ["bench", "recover", "xdog", "--images", str(tmp_path), "--json", str(tmp_path / "r.json")]
    assert main(args) == 2
    assert "no images" in capsys.readouterr().err


def test_random_references_are_never_blank(astronaut: torch.Tensor) -> None:
    effect = effects.create("xdog")
    content = F.interpolate(astronaut, size=(48, 48), mode="area")
    generator = torch.Generator().manual_seed(3)
    for _ in range(6):
        truth, reference = random_reference(effect, content, generator)
        assert truth.shape == (1, len(effect.param_specs)) and truth.abs().max() <= 0.5
        assert float(reference.std()) >= MIN_REFERENCE_CONTRAST


def test_schedule_splits_iterations_between_small_copies_and_full_size_crops() -> None:
    levels, crops = schedule(100, 0.1, "l2")
    assert [reduction for reduction, _ in levels][-1] == 1
    assert sum(s.iterations for _, s in levels) + crops.iterations == 100
    assert levels[0][1].iterations > levels[-1][1].iterations and levels[-1][1].lr < levels[0][1].lr
    assert crops.iterations == 50 and crops.lr < levels[0][1].lr and crops.mode == "global"
    assert schedule(1, 0.1, "l2")[1] is None


def test_an_exact_recovery_counts_as_the_psnr_cap(tmp_path: Path, astronaut: torch.Tensor, monkeypatch) -> None:
    from wise.optimize import benchmark

    photos = tmp_path / "photos"
    photos.mkdir()
    write_image(F.interpolate(astronaut, size=(32, 32), mode="area"), photos / "a.png")

    def same_as_default(effect, content, generator, **options):
        truth = effect.default_params()[None]
        return truth, effect(content, truth)

    monkeypatch.setattr(benchmark, "random_reference", same_as_default)
    with open(tmp_path / "log", "w") as log:
        result = benchmark.recover("xdog", str(photos), trials=1, size=32, iterations=3, lr=1e-6, out=log)
    assert result["trials"][0]["psnr"] == PSNR_CAP and result["mean_psnr"] == PSNR_CAP


def test_crop_iterations_that_leave_the_whole_image_worse_are_dropped(off_the_staircase) -> None:
    case = off_the_staircase
    for loss in ("l1", "l2"):
        for candidates in ([case.truth, case.wrong], [case.wrong, case.truth]):
            assert torch.equal(closest(case.cartoon, case.content, case.target, candidates, loss), case.truth)


def test_of_several_starts_the_trial_keeps_the_one_that_ends_closest(off_the_staircase, monkeypatch) -> None:
    from wise.optimize import benchmark

    case = off_the_staircase
    monkeypatch.setattr(
        benchmark, "random_reference", lambda effect, content, generator, **options: (case.truth, case.target)
    )
    monkeypatch.setattr(benchmark, "inversion_between_levels", lambda *args: None)  # no reading in between
    bins = case.cartoon.param_names.index("bins")
    for starts in ([case.wrong, case.truth], [case.truth, case.wrong]):
        monkeypatch.setattr(benchmark, "read_starts", lambda *args, starts=starts: (starts, ("bins",)))
        levels, crops = benchmark.schedule(4, 1e-4, "l2")
        _, _, outcome = benchmark._trial(case.cartoon, case.content, torch.Generator(), levels, crops, 0)
        assert outcome.params[0, bins] == pytest.approx(float(case.truth[0, bins]), abs=1e-3)
        assert torch.equal(outcome.result, case.cartoon(case.content, outcome.params).detach())


def test_a_start_that_descent_strays_from_is_the_answer(off_the_staircase, monkeypatch) -> None:
    from wise.optimize import benchmark
    from wise.optimize.parametric import Outcome

    case = off_the_staircase
    monkeypatch.setattr(
        benchmark, "random_reference", lambda effect, content, generator, **options: (case.truth, case.target)
    )
    monkeypatch.setattr(benchmark, "read_starts", lambda *args: ([case.truth], ()))
    strayed = Outcome(params=case.wrong.clone(), result=case.cartoon(case.content, case.wrong).detach())
    monkeypatch.setattr(benchmark, "_descend", lambda *args: strayed)
    levels, crops = benchmark.schedule(4, 1e-4, "l2")
    _, _, outcome = benchmark._trial(case.cartoon, case.content, torch.Generator(), levels, crops, 0)
    assert torch.equal(outcome.params, case.truth)
    assert torch.equal(outcome.result, case.target)
