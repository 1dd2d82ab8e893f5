"""The self-contained HTML report of a local training run: loss curves, and for test pairs the
photo, the predicted mask, the result and the target."""

from __future__ import annotations

import html
from pathlib import Path
from typing import Mapping

import torch
from PIL import Image

from wise import params as P
from wise.io import atomic_path, tensor_to_image
from wise.optimize.report import STYLE, heatmap, image_tag, loss_svg, metrics_section
from wise.train.local import LocalGAN
from wise.train.pairs import PairDataset
from wise.train.report import read_curves

PAIRS_SHOWN = 6
SIDE = 192
CURVES = (
    ("train_loss", "training loss (weighted sum)"),
    ("train_l1", "training L1 to the targets"),
    ("val_l1", "test L1 to the targets"),
    ("val_tv", "test masks' total variation"),
    ("train_departure", "masks' departure from the start preset"),
    ("train_d_loss", "discriminator loss"),
)


def shown_parameter(module: LocalGAN, masks: torch.Tensor, task: Mapping[str, object]) -> int:
    """The index of the mask to show: the task's parameter, else the one that varies most."""
    names = module.effect.param_names
    if task.get("parameter") in names:
        return names.index(str(task["parameter"]))
    return int(masks.flatten(2).std(dim=2).mean(dim=0).argmax())


def _figure(image: Image.Image, label: str) -> str:
    return f"<figure>{image_tag(image, label)}<figcaption>{html.escape(label)}</figcaption></figure>"


def _picture(tensor: torch.Tensor) -> Image.Image:
    return Image.fromarray(tensor_to_image(tensor)).resize((SIDE, SIDE), Image.Resampling.BILINEAR)


def pairs_section(module: LocalGAN, test_set: PairDataset, task: Mapping[str, object]) -> str:
    """Rows of photo, predicted mask (heat map over its range), effect stage (with a
    post-processing CNN), result and target."""
    rows = []
    module.network.eval()
    with_stage = module.network.post is not None and module.effect is not None
    for index in range(min(PAIRS_SHOWN, len(test_set))):
        item = test_set[index]
        batch = {"photo": item["photo"][None], "scale": item["scale"], "origin": item["origin"][None]}
        with torch.no_grad():
            masks, stage, made = module.generate(batch)
        l1 = float((made[0] - item["target"]).abs().mean())
        cells = [_figure(_picture(item["photo"][None]), "photo")]
        if masks is not None and masks.dim() == 4:
            cells.append(_mask_figure(module, masks, task))
        if with_stage:
            cells.append(_figure(_picture(stage.clamp(0.0, 1.0)), "effect stage"))
        cells += [_figure(_picture(made), "result"), _figure(_picture(item["target"][None]), "target")]
        rows.append(f'<div class="row">{"".join(cells)}<p>{html.escape(item["name"])}: L1 {l1:.4f}</p></div>')
    heading = "photo, predicted mask, " if module.generator is not None else "photo, "
    heading += "effect stage, result, target" if with_stage else "result, target"
    return f"<section><h2>Test pairs: {heading}</h2>" + "".join(rows) + "</section>"


def _mask_figure(module: LocalGAN, masks: torch.Tensor, task: Mapping[str, object]) -> str:
    specs = module.effect.param_specs
    shown = shown_parameter(module, masks, task)
    spec = specs[shown]
    real_mask = P.to_real(masks, specs)[0, shown]
    picture = Image.fromarray(heatmap(real_mask, spec.min, spec.max)).resize((SIDE, SIDE))
    return _figure(picture, f"{spec.name} [{spec.min:g}, {spec.max:g}]")


def write_local_report(
    path: Path,
    module: LocalGAN,
    test_set: PairDataset,
    metrics_files: list[Path],
    summary: Mapping[str, object],
    task: Mapping[str, object],
) -> None:
    """Write ``report.html`` of a local run (atomically) from its CSV logs; ``task`` is the
    pairs' ``task.json`` ({} for pairs not made by ``wise data adaptive``)."""
    curves = read_curves(metrics_files)
    plots = (
        "".join(f"<h3>{label}</h3>{loss_svg(curves[key])}" for key, label in CURVES if curves.get(key))
        or "<p>No losses were logged.</p>"
    )
    hparams = {k: v for k, v in dict(module.hparams).items() if k != "start"}
    title = html.escape(f"wise: local training of {hparams.get('effect')}")
    shown = {**hparams, **{k: v for k, v in summary.items() if isinstance(v, (int, float, str, bool))}}
    body = f"<h1>{title}</h1>{metrics_section(shown)}<section><h2>Losses</h2>{plots}</section>"
    body += pairs_section(module, test_set, task)
    text = (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>{title}</title><style>{STYLE}</style></head><body>{body}</body></html>\n"
    )
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")
