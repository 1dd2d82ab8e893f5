"""The trial loop the benchmarks share (``wise bench recover`` and ``wise bench ppn``).

Each trial takes the next photo of a folder (cycling), at ``size`` pixels on its short side,
and a generator seeded once for the whole run, so that trial ``i`` of every benchmark with the
same seed and photos sees the same random parameters. The loop prints a Markdown table as the
trials finish; Ctrl-C ends it after dropping the trial in progress, and the finished trials
are summarized and written all the same, marked ``"interrupted": true``.
"""

from __future__ import annotations

import json
import statistics
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence, TextIO

import torch
import torch.nn.functional as F

from wise.effects.base import Effect
from wise.interrupt import ctrl_c
from wise.io import atomic_path, images_in, read_image
from wise.render import render

PSNR_CAP = 60.0
"""PSNR counted for a recovered image identical to the reference (beyond 8-bit precision)."""
MIN_REFERENCE_CONTRAST = 0.05
"""Random parameters whose reference has a smaller standard deviation (a nearly blank image,
which any parameters near the edge of a range reproduce) are drawn again."""
MAX_DRAWS = 20


def random_reference(
    effect: Effect, content: torch.Tensor, generator: torch.Generator, at_reference: bool = True
) -> tuple[torch.Tensor, torch.Tensor]:
    """Random normalized global parameters (1, P) and the reference they render, redrawn while
    the reference is nearly blank: as ``wise apply`` renders, or with ``at_reference=False`` at
    the photo's own scale (for a descent that renders so; the same at 512 pixels and above)."""
    for _ in range(MAX_DRAWS):
        truth = torch.rand(1, len(effect.param_specs), generator=generator) - 0.5
        reference = render(effect, content, truth, at_reference=at_reference)
        if float(reference.std()) >= MIN_REFERENCE_CONTRAST:
            break
    return truth, reference


MOVED_PARAMS = (1, 3)
"""Fewest and most parameters of a preset that an example of :func:`preset_reference` moves."""
MOVED_AT_LEAST = 0.35
"""How far (normalized, of a range of 1) each moved parameter lands from the preset's value."""


def preset_reference(
    effect: Effect, content: torch.Tensor, generator: torch.Generator, number: int
) -> tuple[torch.Tensor, torch.Tensor, dict]:
    """An example as users make them: the effect's presets in turn (trial ``number``), one to
    three of its parameters moved far from the preset's value (at least :data:`MOVED_AT_LEAST`
    of their range), rendered as ``wise apply`` renders; redrawn while nearly blank. Returns
    the normalized parameters (1, P), the example and what was made: the preset and the moved
    values in real units."""
    names = list(effect.presets)
    preset = names[number % len(names)]
    base = effect.preset(preset)
    for _ in range(MAX_DRAWS):
        count = int(torch.randint(MOVED_PARAMS[0], MOVED_PARAMS[1] + 1, (1,), generator=generator))
        moved = torch.randperm(len(effect.param_specs), generator=generator)[:count].tolist()
        truth = base.clone()
        for index in moved:
            # uniform over the parts of [-0.5, 0.5] at least MOVED_AT_LEAST from the preset's value
            below = max(0.0, float(base[index]) + 0.5 - MOVED_AT_LEAST)
            above = max(0.0, 0.5 - float(base[index]) - MOVED_AT_LEAST)
            draw = float(torch.rand(1, generator=generator)) * (below + above)
            truth[index] = -0.5 + draw if draw < below else float(base[index]) + MOVED_AT_LEAST + (draw - below)
        reference = render(effect, content, truth[None])
        if float(reference.std()) >= MIN_REFERENCE_CONTRAST:
            break
    values = effect.params_to_dict(truth)
    made = {
        "preset": preset,
        "moved": {effect.param_specs[index].name: values[effect.param_specs[index].name] for index in sorted(moved)},
    }
    return truth[None], reference, made


def content_at(photo: torch.Tensor, size: int) -> torch.Tensor:
    """The photo with its short side at ``size``."""
    factor = size / min(photo.shape[-2:])
    shape = (max(8, round(photo.shape[-2] * factor)), max(8, round(photo.shape[-1] * factor)))
    return F.interpolate(photo, size=shape, mode="area" if factor < 1 else "bilinear")


@dataclass(frozen=True)
class Column:
    """A column of the printed table: its heading, the row's key and the number format."""

    heading: str
    key: str
    format: str = ".4f"


Trial = Callable[[int, Path, torch.Tensor, torch.Generator], dict]
"""(trial number, photo file, photo at the benchmark's size, generator) -> the trial's row;
raising KeyboardInterrupt drops the trial."""


def run_trials(
    images_dir: str,
    trials: int,
    size: int,
    seed: int,
    trial: Trial,
    columns: Sequence[Column],
    summarize: Callable[[list[dict], bool], dict],
    json_path: str | None,
    out: TextIO,
) -> dict:
    """Run ``trials`` trials, print their rows, and return (and write to ``json_path``) the
    summary of the finished ones with ``interrupted`` set."""
    photos = images_in(images_dir)
    contents = {path: content_at(read_image(path), size) for path in photos[:trials]}
    generator = torch.Generator().manual_seed(seed)
    headings = ["trial", "image", *(c.heading for c in columns)]
    print("| " + " | ".join(headings) + " |\n|" + " --- |" * len(headings), file=out)
    rows: list[dict] = []
    with ctrl_c(out) as interruption:
        try:
            for number in range(trials):
                path = photos[number % len(photos)]
                row = {"trial": number, "image": path.name, **trial(number, path, contents[path], generator)}
                rows.append(row)
                cells = [str(number), path.name, *(f"{row[c.key]:{c.format}}" for c in columns)]
                print("| " + " | ".join(cells) + " |", file=out, flush=True)
        except KeyboardInterrupt:
            print(f"interrupted: {len(rows)} of {trials} trials finished", file=out, flush=True)
        interruption.hold()
        result = summarize(rows, interruption.received)
        result["interrupted"] = interruption.received
        if json_path is not None:
            with atomic_path(json_path) as tmp:
                Path(tmp).write_text(json.dumps(result, indent=2) + "\n")
    result["interrupted"] = result["interrupted"] or interruption.received
    return result


def mean_of(rows: list[dict], key: str) -> float | None:
    """The mean of a column over the finished trials (None when none finished or none has it)."""
    values = [row[key] for row in rows if row.get(key) is not None]
    return statistics.fmean(values) if values else None


def worst_of(rows: list[dict], key: str) -> float | None:
    """The lowest value of a column over the finished trials (None when none has it)."""
    values = [row[key] for row in rows if row.get(key) is not None]
    return min(values) if values else None
