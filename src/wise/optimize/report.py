"""Self-contained HTML reports and GIF animations of parametric style transfer runs.

The report is one HTML file with no external resources: images are embedded as
base64 PNG data URIs, the loss curve is an inline SVG and colour bars are CSS
gradients. Both writers are atomic (temporary file in the target directory,
then :func:`os.replace`).
"""

from __future__ import annotations

import base64
import html
import io
import math
from typing import Mapping, Protocol, Sequence

import numpy as np
import torch
from PIL import Image, ImageDraw

from wise import params as P
from wise.io import PathLike, atomic_path, tensor_to_image
from wise.params import ParamSpec

PAGE_MAX_SIDE = 512
ANIMATION_MAX_SIDE = 384
HEATMAP_SIDE = 192

VIRIDIS_STOPS = np.array(
    [
        [68, 1, 84],
        [59, 82, 139],
        [33, 145, 140],
        [94, 201, 98],
        [253, 231, 37],
    ],
    dtype=np.float64,
)

Metric = float | int | str


class EffectLike(Protocol):
    """What the report needs of an effect."""

    name: str

    @property
    def param_specs(self) -> Sequence[ParamSpec]: ...

    @property
    def param_names(self) -> list[str]: ...


def heatmap(values: np.ndarray | torch.Tensor, low: float, high: float) -> np.ndarray:
    """Map an ``H x W`` array to ``H x W x 3`` uint8 with a viridis-like ramp.

    ``low`` maps to the first colour stop and ``high`` to the last; values outside
    are clamped, NaN maps to ``low``.
    """
    if isinstance(values, torch.Tensor):
        values = values.detach().to("cpu", torch.float64).numpy()
    array = np.asarray(values, dtype=np.float64)
    if array.ndim != 2:
        raise ValueError(f"heatmap expects an H x W array, got shape {array.shape}")
    span = float(high) - float(low)
    if not math.isfinite(span) or span <= 0:
        t = np.where(array >= high, 1.0, 0.0)
    else:
        t = (array - float(low)) / span
    t = np.clip(np.nan_to_num(t, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    position = t * (len(VIRIDIS_STOPS) - 1)
    index = np.minimum(np.floor(position).astype(np.int64), len(VIRIDIS_STOPS) - 2)
    frac = (position - index)[..., None]
    colours = VIRIDIS_STOPS[index] * (1.0 - frac) + VIRIDIS_STOPS[index + 1] * frac
    return np.round(colours).astype(np.uint8)


SHEET_COLUMNS = 4
SHEET_LABEL_HEIGHT = 14
SHEET_GAP = 4


def shown_span(spec: ParamSpec, mask: np.ndarray | torch.Tensor) -> tuple[float, float]:
    """The span a mask's heat map covers: its parameter's range, widened to the mask's values
    where they leave it (colour offsets fitted to a reference may)."""
    return min(spec.min, float(mask.min())), max(spec.max, float(mask.max()))


def mask_sheet(params: torch.Tensor, specs: Sequence[ParamSpec], side: int = HEATMAP_SIDE) -> Image.Image:
    """Every mask of normalized ``(1, P, h, w)`` parameters as a heat map over its parameter's
    range (:func:`shown_span`), labelled with its name and that span, in rows of four on white."""
    if params.dim() != 4 or params.shape[:2] != (1, len(specs)):
        raise ValueError(f"mask_sheet needs (1, {len(specs)}, h, w) masks, got {tuple(params.shape)}")
    real = P.to_real(params.detach().to("cpu", torch.float64), specs)[0]
    height, width = real.shape[-2:]
    scale = side / max(height, width)
    cell = (max(1, round(width * scale)), max(1, round(height * scale)))
    columns = min(SHEET_COLUMNS, len(specs))
    rows = math.ceil(len(specs) / columns)
    pitch = (cell[0] + SHEET_GAP, cell[1] + SHEET_LABEL_HEIGHT + SHEET_GAP)
    sheet = Image.new("RGB", (columns * pitch[0], rows * pitch[1]), "white")
    draw = ImageDraw.Draw(sheet)
    for index, (spec, mask) in enumerate(zip(specs, real)):
        left, top = (index % columns) * pitch[0], (index // columns) * pitch[1]
        low, high = shown_span(spec, mask)
        draw.text((left, top), f"{spec.name} [{_num(low)}, {_num(high)}]", fill="black")
        tile = Image.fromarray(heatmap(mask, low, high)).resize(cell, Image.Resampling.BILINEAR)
        sheet.paste(tile, (left, top + SHEET_LABEL_HEIGHT))
    return sheet


def fit_image(image: Image.Image, max_side: int, resample: Image.Resampling = Image.Resampling.LANCZOS) -> Image.Image:
    """Downscale ``image`` so its long side is at most ``max_side``."""
    long_side = max(image.size)
    if long_side <= max_side:
        return image
    scale = max_side / long_side
    size = (max(1, round(image.width * scale)), max(1, round(image.height * scale)))
    return image.resize(size, resample)


def _data_uri(image: Image.Image) -> str:
    buffer = io.BytesIO()
    image.save(buffer, format="PNG", optimize=True)
    return "data:image/png;base64," + base64.b64encode(buffer.getvalue()).decode("ascii")


def image_tag(image: Image.Image, alt: str, css_class: str = "") -> str:
    cls = f' class="{css_class}"' if css_class else ""
    return f'<img{cls} src="{_data_uri(image)}" width="{image.width}" height="{image.height}" alt="{html.escape(alt)}">'


def _fmt(value: Metric) -> str:
    if isinstance(value, bool) or isinstance(value, (int, str)):
        return str(value)
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def _num(value: float) -> str:
    return f"{value:.4g}"


def _images_section(content: torch.Tensor, target: torch.Tensor, result: torch.Tensor) -> str:
    figures = []
    for label, tensor in (("content", content), ("target", target), ("result", result)):
        image = fit_image(Image.fromarray(tensor_to_image(tensor)), PAGE_MAX_SIDE)
        figures.append(f"<figure>{image_tag(image, label)}<figcaption>{label}</figcaption></figure>")
    return '<section><h2>Images</h2><div class="row">' + "".join(figures) + "</div></section>"


def metrics_section(metrics: Mapping[str, Metric]) -> str:
    if not metrics:
        return "<section><h2>Metrics</h2><p>No metrics.</p></section>"
    rows = "".join(
        f"<tr><th>{html.escape(str(k))}</th><td>{html.escape(_fmt(v))}</td></tr>" for k, v in metrics.items()
    )
    return f"<section><h2>Metrics</h2><table>{rows}</table></section>"


def loss_svg(losses: Sequence[float], width: int = 520, height: int = 260) -> str:
    """The loss curve as an inline SVG with one polyline point per loss."""
    values = np.asarray([float(v) for v in losses], dtype=np.float64)
    if values.size == 0:
        return "<p>No losses recorded.</p>"
    finite = values[np.isfinite(values)]
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    if hi <= lo:
        lo, hi = lo - 0.5, hi + 0.5
    values = np.clip(np.nan_to_num(values, nan=hi, posinf=hi, neginf=lo), lo, hi)
    left, right, top, bottom = 64, 16, 16, 44
    plot_w, plot_h = width - left - right, height - top - bottom
    n = values.size
    xs = left + (np.arange(n) / max(n - 1, 1)) * plot_w
    ys = top + (hi - values) / (hi - lo) * plot_h
    points = " ".join(f"{x:.2f},{y:.2f}" for x, y in zip(xs, ys))
    x0, x1, y0, y1 = left, left + plot_w, top, top + plot_h
    return (
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
        f'viewBox="0 0 {width} {height}" role="img" aria-label="loss curve">'
        f'<rect x="{x0}" y="{y0}" width="{plot_w}" height="{plot_h}" fill="#fafafa" stroke="none"/>'
        f'<line x1="{x0}" y1="{y1}" x2="{x1}" y2="{y1}" stroke="#333"/>'
        f'<line x1="{x0}" y1="{y0}" x2="{x0}" y2="{y1}" stroke="#333"/>'
        f'<polyline fill="none" stroke="#3b528b" stroke-width="1.5" points="{points}"/>'
        f'<text x="{x0}" y="{y1 + 16}" text-anchor="middle">1</text>'
        f'<text x="{x1}" y="{y1 + 16}" text-anchor="middle">{n}</text>'
        f'<text x="{x0 - 6}" y="{y1}" text-anchor="end">{html.escape(_num(lo))}</text>'
        f'<text x="{x0 - 6}" y="{y0 + 10}" text-anchor="end">{html.escape(_num(hi))}</text>'
        f'<text x="{(x0 + x1) / 2:.1f}" y="{height - 6}" text-anchor="middle">iteration</text>'
        f'<text x="14" y="{(y0 + y1) / 2:.1f}" text-anchor="middle" '
        f'transform="rotate(-90 14 {(y0 + y1) / 2:.1f})">loss</text>'
        "</svg>"
    )


def _colour_bar(low: float, high: float) -> str:
    stops = ", ".join(
        f"rgb({r:.0f},{g:.0f},{b:.0f}) {100 * i / (len(VIRIDIS_STOPS) - 1):.0f}%"
        for i, (r, g, b) in enumerate(VIRIDIS_STOPS)
    )
    return (
        f'<div class="bar" style="background: linear-gradient(to right, {stops});"></div>'
        f'<div class="bar-labels"><span>{html.escape(_num(low))}</span>'
        f"<span>{html.escape(_num(high))}</span></div>"
    )


def _global_params_section(real: np.ndarray, specs: Sequence[ParamSpec]) -> str:
    rows = "".join(
        f"<tr><th>{html.escape(s.name)}</th><td>{html.escape(_num(float(v)))}</td>"
        f"<td>[{html.escape(_num(s.min))}, {html.escape(_num(s.max))}]</td>"
        f"<td>{html.escape(_num(s.default))}</td></tr>"
        for s, v in zip(specs, real)
    )
    return (
        "<section><h2>Parameters (global)</h2><table>"
        "<tr><th>parameter</th><th>value</th><th>range</th><th>default</th></tr>"
        f"{rows}</table></section>"
    )


def _local_params_section(real: np.ndarray, specs: Sequence[ParamSpec]) -> str:
    cards = []
    for spec, mask in zip(specs, real):
        low, high = shown_span(spec, mask)
        image = Image.fromarray(heatmap(mask, low, high))
        scale = HEATMAP_SIDE / max(image.size)
        size = (max(1, round(image.width * scale)), max(1, round(image.height * scale)))
        resample = Image.Resampling.NEAREST if scale >= 1 else Image.Resampling.BILINEAR
        image = image.resize(size, resample)
        name = html.escape(spec.name)
        cards.append(
            '<div class="card">'
            f"<h3>{name}</h3>"
            f"{image_tag(image, spec.name, 'mask')}"
            f"{_colour_bar(low, high)}"
            f'<p class="range">range [{html.escape(_num(spec.min))}, {html.escape(_num(spec.max))}]</p>'
            f'<p class="stats">min {html.escape(_num(float(mask.min())))} · '
            f"mean {html.escape(_num(float(mask.mean())))} · "
            f"max {html.escape(_num(float(mask.max())))}</p>"
            "</div>"
        )
    return '<section><h2>Parameter masks</h2><div class="row">' + "".join(cards) + "</div></section>"


def _params_section(params: torch.Tensor, specs: Sequence[ParamSpec]) -> str:
    t = params.detach().to("cpu", torch.float64)
    if t.dim() == 1:
        t = t.unsqueeze(0)
    if t.dim() not in (2, 4) or t.shape[0] != 1 or t.shape[1] != len(specs):
        raise ValueError(
            f"params must have shape (1, {len(specs)}) or (1, {len(specs)}, h, w); got {tuple(params.shape)}"
        )
    real = P.to_real(t, specs)[0].numpy()
    if t.dim() == 2:
        return _global_params_section(real, specs)
    return _local_params_section(real, specs)


STYLE = """
body { font-family: system-ui, sans-serif; margin: 24px; color: #222; }
.row { display: flex; flex-wrap: wrap; gap: 16px; align-items: flex-start; }
figure { margin: 0; text-align: center; }
table { border-collapse: collapse; }
th, td { border: 1px solid #ccc; padding: 4px 10px; text-align: left; }
.card { border: 1px solid #ddd; padding: 8px; width: 200px; }
.card h3 { margin: 0 0 6px 0; font-size: 1em; word-break: break-all; }
img.mask { image-rendering: pixelated; display: block; }
.bar { height: 12px; width: 192px; margin-top: 6px; }
.bar-labels { display: flex; justify-content: space-between; width: 192px; font-size: 0.8em; }
.range, .stats { margin: 4px 0; font-size: 0.85em; }
svg text { font-size: 12px; fill: #333; }
"""


def render_report(
    effect: EffectLike,
    content: torch.Tensor,
    target: torch.Tensor,
    result: torch.Tensor,
    params: torch.Tensor,
    losses: Sequence[float],
    metrics: Mapping[str, Metric],
) -> str:
    """The report as an HTML string (see :func:`write_report`)."""
    specs = tuple(effect.param_specs)
    title = html.escape(f"wise: {effect.name}")
    body = "".join(
        [
            f"<h1>{title}</h1>",
            _images_section(content, target, result),
            metrics_section(metrics),
            f"<section><h2>Loss</h2>{loss_svg(losses)}</section>",
            _params_section(params, specs),
        ]
    )
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>{title}</title><style>{STYLE}</style></head>"
        f"<body>{body}</body></html>\n"
    )


def write_report(
    path: PathLike,
    effect: EffectLike,
    content: torch.Tensor,
    target: torch.Tensor,
    result: torch.Tensor,
    params: torch.Tensor,
    losses: Sequence[float],
    metrics: Mapping[str, Metric],
) -> None:
    """Write a self-contained HTML report of a parametric style transfer run.

    ``content``, ``target`` and ``result`` are ``(1, 3, H, W)`` tensors in [0, 1];
    ``params`` are normalized, global ``(1, P)`` or local masks ``(1, P, h, w)``;
    ``losses`` holds one value per iteration. The write is atomic.
    """
    text = render_report(effect, content, target, result, params, losses, metrics)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_animation(path: PathLike, frames: Sequence[np.ndarray], duration_ms: int = 80) -> None:
    """Write ``H x W x 3`` uint8 frames as a looping GIF, at most 384 px on the long side.

    All frames take the size of the first. Pillow merges identical consecutive
    frames. The write is atomic.
    """
    if len(frames) == 0:
        raise ValueError("write_animation needs at least one frame")
    if duration_ms <= 0:
        raise ValueError(f"duration_ms must be positive, got {duration_ms}")
    images = []
    size: tuple[int, int] | None = None
    for i, frame in enumerate(frames):
        array = np.asarray(frame)
        if array.ndim != 3 or array.shape[2] != 3 or array.dtype != np.uint8 or 0 in array.shape[:2]:
            raise ValueError(f"frame {i} must be a non-empty H x W x 3 uint8 array, got {array.dtype} {array.shape}")
        image = Image.fromarray(array)
        if size is None:
            image = fit_image(image, ANIMATION_MAX_SIDE)
            size = image.size
        elif image.size != size:
            image = image.resize(size, Image.Resampling.LANCZOS)
        images.append(image)
    with atomic_path(path) as tmp:
        images[0].save(
            tmp,
            format="GIF",
            save_all=True,
            append_images=images[1:],
            duration=int(duration_ms),
            loop=0,
        )
