"""Every command draws a picture the same way: ``apply``, the answer of ``predict``, the result
of ``optimize`` and the examples of ``bench ppn`` agree for the same parameters, also below the
reference size, where the picture is drawn enlarged and reduced (:func:`wise.render.render`)."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from skimage import data

import wise
from wise.io import read_image, write_image
from wise.optimize.trials import content_at, random_reference
from wise.paramfile import save_params
from wise.render import Look, render

from .helpers import run_in_process

ROUNDING = 1.5 / 255
"""Two 8-bit files of the same render differ by rounding at most (one more step for the resampling
of a file read back)."""


def _photo(short: int) -> torch.Tensor:
    """Chelsea (a landscape picture) with its short side at ``short``."""
    return content_at(torch.from_numpy(data.chelsea()).permute(2, 0, 1)[None].float() / 255, short)


def _applied(tmp_path: Path, photo: Path, params: Path, name: str) -> torch.Tensor:
    out = tmp_path / f"applied-{name}.png"
    code, _ = run_in_process(["apply", "xdog", str(photo), "--params", str(params), "-o", str(out), "--quiet"])
    assert code == 0
    return read_image(out)


@pytest.mark.parametrize("short", [256, 320, 512])
def test_apply_predict_optimize_and_bench_draw_the_same_picture(
    tmp_path: Path, short: int, brief_readings: None
) -> None:
    effect = wise.effects.create("xdog")
    content = _photo(short)
    truth = effect.params_from_dict({"contour": 2.0, "details": 1.5, "blackness": 0.3}, preset="portrait")[None]
    photo, params = tmp_path / "photo.png", tmp_path / "truth.safetensors"
    write_image(content, photo)
    content = read_image(photo)  # the 8-bit photo every command reads
    save_params(params, effect, truth)
    example = _applied(tmp_path, photo, params, "truth")
    assert (example - render(effect, content, truth)).abs().max() <= ROUNDING

    # the look descent fits is the one apply draws, not the picture's own scale
    look = Look(effect, content)
    with torch.no_grad():
        assert (look(truth) - render(effect, content, truth)).abs().max() < 1e-3
        box = look.box(truth, 40, 60, 48, 48, context=24)  # a crop of descent: its context reaches most of the pipeline
        assert (box - look(truth)[..., 40:88, 60:108]).abs().mean() < 1e-3
    if short < 512:
        own_scale = effect(content, truth)
        assert (own_scale - example).abs().mean() > 4 * ROUNDING, "the lines at a small picture's own scale differ"

    target = tmp_path / "example.png"
    write_image(example, target)
    predicted = tmp_path / "predicted"  # the refinement's descent fits this look: tests/optimize/test_refine.py
    code, _ = run_in_process(
        ["predict", "xdog", "--content", str(photo), "--target", str(target), "-o", str(predicted), "--refine", "0"]
    )
    assert code == 0
    answer = _applied(tmp_path, photo, predicted / "params.safetensors", "predicted")
    assert (read_image(predicted / "result.png") - answer).abs().max() <= ROUNDING

    optimized = tmp_path / "optimized"
    code, _ = run_in_process(
        [
            "optimize", "xdog", "--content", str(photo), "--target", str(target), "-o", str(optimized),
            "--mode", "global", "--iters", "1", "--size", str(short),
        ]
    )  # fmt: skip
    assert code == 0
    result = _applied(tmp_path, photo, optimized / "params.safetensors", "optimized")
    assert (read_image(optimized / "result.png") - result).abs().max() <= ROUNDING

    generator = torch.Generator().manual_seed(3)
    drawn, bench_example = random_reference(effect, content, generator)
    assert torch.allclose(bench_example, render(effect, content, drawn))
