"""The results page of ``wise bench pairs --html``: the means, and for the first pairs the
photo, the effect stage, the final image, the ground truth and the predicted masks (as in
WISE's Fig. 8 and 9)."""

from __future__ import annotations

import html
from pathlib import Path

import torch
from PIL import Image

from wise import params as P
from wise.effects.base import Effect
from wise.io import atomic_path, read_image, tensor_to_image
from wise.optimize.report import STYLE, heatmap, image_tag, metrics_section
from wise.ppn.translation import Stages
from wise.train.pairs import Pair

PAGE_PAIRS = 12
"""Pairs shown on the page (all are measured)."""
MASKS_SHOWN = 3
"""The masks that vary most over a picture are shown, at most this many."""
SIDE = 192


def _figure(image: Image.Image, label: str) -> str:
    return f"<figure>{image_tag(image, label)}<figcaption>{html.escape(label)}</figcaption></figure>"


def _picture(tensor: torch.Tensor) -> Image.Image:
    picture = Image.fromarray(tensor_to_image(tensor.clamp(0.0, 1.0)))
    return picture.resize((SIDE, round(SIDE * picture.height / picture.width)), Image.Resampling.BILINEAR)


def mask_figures(masks: torch.Tensor, effect: Effect) -> list[str]:
    """Heat maps of the :data:`MASKS_SHOWN` masks of ``(1, P, h, w)`` that vary most."""
    spread = masks[0].flatten(1).std(dim=1)
    order = [int(i) for i in spread.argsort(descending=True)[:MASKS_SHOWN]]
    real = P.to_real(masks, effect.param_specs)[0]
    figures = []
    for index in order:
        spec = effect.param_specs[index]
        picture = Image.fromarray(heatmap(real[index], spec.min, spec.max))
        picture = picture.resize((SIDE, round(SIDE * picture.height / picture.width)))
        figures.append(_figure(picture, f"{spec.name} [{spec.min:g}, {spec.max:g}]"))
    return figures


def write_pairs_page(path: str | Path, summary: dict, shown: list[tuple[Pair, Stages]], effect: Effect | None) -> None:
    """Write the page (atomically) from :func:`wise.train.evaluate.bench_pairs`' summary."""
    means = {k: v for k, v in summary.items() if isinstance(v, (int, float, str)) and k != "rows"}
    rows = []
    for (pair, made), row in zip(shown, summary["rows"]):
        cells = [_figure(_picture(read_image(pair.photo)), "photo")]
        if effect is not None and made.stage is not made.result:
            cells.append(_figure(_picture(made.stage), "effect stage"))
        cells.append(_figure(_picture(made.result), "result"))
        cells.append(_figure(_picture(read_image(pair.target)), "ground truth"))
        if effect is not None and made.masks is not None and made.masks.dim() == 4:
            cells += mask_figures(made.masks, effect)
        caption = f"{pair.name}: L1 {row['l1']:.4f}, PSNR {row['psnr']:.2f} dB, SSIM {row['ssim']:.4f}"
        rows.append(f'<div class="row">{"".join(cells)}<p>{html.escape(caption)}</p></div>')
    title = html.escape(f"wise: {summary['model']} on {summary['pairs']}")
    body = f"<h1>{title}</h1>{metrics_section(means)}<section><h2>Pairs</h2>{''.join(rows)}</section>"
    text = (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>{title}</title><style>{STYLE}</style></head><body>{body}</body></html>\n"
    )
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")
