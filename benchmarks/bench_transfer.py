"""Parametric style transfer onto neural style transfer references, with the default settings.

Usage::

    python benchmarks/bench_transfer.py CONTENT --styles 0 12 path/to/style.jpg [--effects ...]
        [--size 512] [--out DIR]

For every style (a built-in style index of the ONNX networks or a style image) the reference
is made once at the working size; then ``wise optimize EFFECT`` with its default settings
(local masks, L1 loss) re-creates it. Prints a Markdown table of L1, PSNR, SSIM and the share
of pixels more than 30 ΔE from the reference's colour (:func:`wise.metrics.far_colour_share`)
against the reference at the working size, the optimization time and that of the whole run (with
the full-resolution render, report and animation), per effect and style, with each effect's
mean L1.

With ``--highres PX`` the masks found are also rendered with the content resized to a
PX-pixel short side (``wise apply --params``), and that render, reduced to the working size,
is compared with the working-size result: the masks carry over when the two agree.
"""

from __future__ import annotations

import wise  # before torch, as the command line: OpenMP waits without spinning

# isort: split
import argparse
import io
import json
import statistics
import tempfile
import time
from pathlib import Path

import torch.nn.functional as F

from wise import metrics
from wise.io import read_image, write_image
from wise.nst import stylize
from wise.optimize.parametric import Settings
from wise.optimize.run import run, working_size
from wise.paramfile import load_params
from wise.render import render


def reference(content_path: Path, style: str, size: int, folder: Path) -> Path:
    content = read_image(content_path)
    small = F.interpolate(content, size=working_size(*content.shape[-2:], size), mode="area")
    if style.isdigit():
        stylized = stylize(small, builtin_style=int(style))
    else:
        stylized = stylize(small, style=read_image(style))
    path = folder / f"reference_{Path(style).stem}.png"
    write_image(stylized, path)
    return path


def highres_agreement(content_path: Path, out_dir: Path, effect_name: str, short_side: int) -> str:
    """Render the masks of ``out_dir`` at ``short_side`` pixels; L1 and SSIM of that render,
    reduced to the working size, against the working-size result. Saves ``highres.png``."""
    effect = wise.effects.create(effect_name)
    content = read_image(content_path)
    params = load_params(out_dir / "params.safetensors", effect)
    small = render(effect, F.interpolate(content, size=params.shape[-2:], mode="area"), params)
    factor = short_side / min(content.shape[-2:])
    size = (round(content.shape[-2] * factor), round(content.shape[-1] * factor))
    large = render(effect, F.interpolate(content, size=size, mode="bicubic").clamp(0, 1), params)
    write_image(large, out_dir / "highres.png")
    reduced = F.interpolate(large, size=small.shape[-2:], mode="area")
    return f" {metrics.l1(reduced, small):.4f}, {metrics.ssim(reduced, small):.3f} |"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("content", type=Path)
    parser.add_argument("--styles", nargs="+", required=True, help="built-in style indices or style images")
    parser.add_argument("--effects", nargs="+", default=wise.effects.available())
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--out", type=Path, help="keep the outputs here (default: a temporary folder)")
    parser.add_argument("--highres", type=int, help="also render the masks at this short side and compare")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as scratch:
        folder = args.out or Path(scratch)
        folder.mkdir(parents=True, exist_ok=True)
        references = {style: reference(args.content, style, args.size, folder) for style in args.styles}
        header = "| effect | style | L1 | PSNR | SSIM | ΔE > 30 | optimization | whole run |"
        if args.highres:
            header += f" {args.highres} px vs {args.size} px (L1, SSIM) |"
        print(header + "\n" + "| --- " * (header.count(" | ") + 1) + "|")
        for effect in args.effects:
            l1s = []
            for style, target in references.items():
                out_dir = folder / f"{effect}_{Path(style).stem}"
                start = time.perf_counter()
                run(effect, str(args.content), str(target), str(out_dir), Settings(), size=args.size, out=io.StringIO())
                wall = time.perf_counter() - start
                scores = json.loads((out_dir / "metrics.json").read_text())
                l1s.append(scores["l1"])
                wanted = read_image(target)
                made = F.interpolate(read_image(out_dir / "result.png"), size=wanted.shape[-2:], mode="area")
                far = metrics.far_colour_share(made, wanted)
                print(
                    f"| {effect} | {Path(style).stem} | {scores['l1']:.4f} | {scores['psnr']:.2f} dB "
                    f"| {scores['ssim']:.3f} | {100 * far:.1f} % "
                    f"| {scores['seconds'] / 60:.1f} min | {wall / 60:.1f} min |"
                    + (highres_agreement(args.content, out_dir, effect, args.highres) if args.highres else ""),
                    flush=True,
                )
            print(f"| {effect} | mean | {statistics.fmean(l1s):.4f} | | | | | |", flush=True)


if __name__ == "__main__":
    main()
