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

PSNR_CAP = 60.0
"""PSNR counted for a recovered image identical to the reference (beyond 8-bit precision)."""
MIN_REFERENCE_CONTRAST = 0.05
"""Random parameters whose reference has a smaller standard deviation (a nearly blank image,
which any parameters near the edge of a range reproduce) are drawn again."""
MAX_DRAWS = 20


def random_reference(
    effect: Effect, content: torch.Tensor, generator: torch.Generator
) -> tuple[torch.Tensor, torch.Tensor]:
    """Random normalized global parameters (1, P) and the reference they render, redrawn while
    the reference is nearly blank."""
    for _ in range(MAX_DRAWS):
        truth = torch.rand(1, len(effect.param_specs), generator=generator) - 0.5
        with torch.no_grad():
            reference = effect(content, truth)
        if float(reference.std()) >= MIN_REFERENCE_CONTRAST:
            break
    return truth, reference


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
