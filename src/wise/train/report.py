"""The self-contained HTML report of a training run: loss curves and validation triples."""

from __future__ import annotations

import csv
import html
import math
from pathlib import Path
from typing import Mapping

import torch
import torch.nn.functional as F
from PIL import Image

from wise.io import atomic_path, tensor_to_image
from wise.optimize.report import STYLE, image_tag, loss_svg, metrics_section
from wise.train.data import ExampleDataset
from wise.train.module import GlobalPPN

TRIPLES = 6
TRIPLE_SIDE = 160
CURVES = (("train_loss", "training loss"), ("val_loss", "validation loss"), ("val_param_l1", "validation parameter L1"))


def read_curves(metrics_files: list[Path]) -> dict[str, list[float]]:
    """The logged values of each column of Lightning's ``metrics.csv`` files, in order."""
    curves: dict[str, list[float]] = {}
    for metrics_csv in metrics_files:
        if metrics_csv.is_file():
            _read_curves(metrics_csv, curves)
    return curves


def _read_curves(metrics_csv: Path, curves: dict[str, list[float]]) -> None:
    with metrics_csv.open(newline="") as f:
        for row in csv.DictReader(f):
            for key, value in row.items():
                if key and value not in (None, ""):
                    try:
                        number = float(value)
                    except ValueError:
                        continue
                    if math.isfinite(number):
                        curves.setdefault(key, []).append(number)


def _triples(module: GlobalPPN, validation: ExampleDataset) -> str:
    rows = []
    network = module.network.eval()
    device = next(network.parameters()).device
    for index in range(min(TRIPLES, len(validation))):
        item = validation[index]
        photo, example = item["photo"][None], item["example"][None]
        with torch.no_grad():
            predicted = network(photo.to(device), example.to(device)).float().cpu()
        tile = F.interpolate(photo, size=(validation.tile, validation.tile), mode="bilinear", align_corners=False)
        rendered = validation.reduced(validation.render(tile.clamp(0.0, 1.0), predicted))
        error = float((predicted[0] - item["params"]).abs().mean())
        cells = []
        for label, image in (("photo", photo), ("example", example), ("prediction", rendered)):
            picture = Image.fromarray(tensor_to_image(image)).resize((TRIPLE_SIDE, TRIPLE_SIDE))
            cells.append(f"<figure>{image_tag(picture, label)}<figcaption>{label}</figcaption></figure>")
        rows.append(f'<div class="row">{"".join(cells)}<p>parameter L1 {error:.3f}</p></div>')
    return "<section><h2>Validation: photo, example, prediction</h2>" + "".join(rows) + "</section>"


def write_training_report(
    path: Path, module: GlobalPPN, validation: ExampleDataset, metrics_files: list[Path], summary: Mapping[str, object]
) -> None:
    """Write ``report.html`` of a run (atomically) from its CSV logs."""
    curves = read_curves(metrics_files)
    plots = (
        "".join(f"<h3>{label}</h3>{loss_svg(curves[key])}" for key, label in CURVES if curves.get(key))
        or "<p>No losses were logged.</p>"
    )
    hparams = dict(module.hparams)
    title = html.escape(
        f"wise: training {hparams.get('effect')} ({hparams.get('architecture')}, {hparams.get('loss')})"
    )
    shown = {**hparams, **{k: v for k, v in summary.items() if isinstance(v, (int, float, str, bool))}}
    body = f"<h1>{title}</h1>{metrics_section(shown)}<section><h2>Losses</h2>{plots}</section>"
    body += _triples(module, validation)
    text = (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>{title}</title><style>{STYLE}</style></head><body>{body}</body></html>\n"
    )
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")
