"""The demo: parametric style transfer of a bundled photo, and the XDoG presets.

Run it with ``make demo`` or ``python -m wise.demo [--out DIR]``. The photo is
``skimage.data.astronaut()`` (NASA, public domain), which ships with scikit-image. A built-in
neural style (an offline ONNX network) stylizes it; the watercolor effect's parameter masks are
then optimized to re-create that reference, and a report shows the result and the masks.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import time
from pathlib import Path

import torch
from skimage import data

import wise
from wise.io import image_to_tensor, write_image
from wise.optimize.parametric import Settings
from wise.optimize.run import transfer
from wise.paramfile import save_params


def run(out_dir: Path) -> list[Path]:
    """Render every XDoG preset on the astronaut into ``out_dir``; return the written files."""
    out_dir.mkdir(parents=True, exist_ok=True)
    photo = image_to_tensor(data.astronaut())
    written = [out_dir / "astronaut.png"]
    write_image(photo, written[0])
    effect = wise.effects.create("xdog")
    for preset in effect.presets:
        params = effect.preset(preset)[None]
        start = time.perf_counter()
        with torch.no_grad():
            result = effect(photo, params)
        seconds = time.perf_counter() - start
        image_path, params_path = out_dir / f"xdog_{preset}.png", out_dir / f"xdog_{preset}.safetensors"
        write_image(result, image_path)
        save_params(params_path, effect, params)
        written += [image_path, params_path]
        print(f"xdog {preset:9s} {tuple(photo.shape[-2:])} in {seconds:.2f} s -> {image_path}")
    return written


DEMO_STYLE = 0
"""A soft painterly built-in style."""
DEMO_SIZE = 256
DEMO_ITERATIONS = 200


def transfer_demo(out_dir: Path) -> Path:
    """``wise transfer watercolor`` on the astronaut with a built-in style; returns the report."""
    folder = out_dir / "transfer"
    settings = Settings(iterations=DEMO_ITERATIONS)
    transfer(
        "watercolor", str(out_dir / "astronaut.png"), str(folder), settings, builtin_style=DEMO_STYLE, size=DEMO_SIZE
    )
    return folder / "report.html"


def wise_command() -> str:
    """How to call ``wise`` from this shell: ``wise`` where it is on the PATH, else the script
    beside this Python (``.venv/bin/wise`` after ``make demo``, relative to the current folder)."""
    script = Path(sys.executable).parent / "wise"
    on_path = shutil.which("wise")
    if not script.exists() or (on_path is not None and Path(on_path).resolve() == script.resolve()):
        return "wise"
    try:
        return str(script.relative_to(Path.cwd()))
    except ValueError:
        return str(script)


def hints(out_dir: Path, report: Path) -> list[str]:
    """The commands the demo suggests at its end, runnable as printed from the current folder."""
    wise_cli = wise_command()
    return [
        f"Open the parametric style transfer report: {report}",
        f"Paint its masks in the web editor: {wise_cli} edit {out_dir / 'astronaut.png'} "
        f"--params {report.parent / 'params.safetensors'} (or: make edit)",
        f"Re-render or edit with: {wise_cli} apply xdog {out_dir / 'astronaut.png'} "
        f"--params {out_dir / 'xdog_portrait.safetensors'} -o {out_dir / 'edited.png'} --set blackness=0.3",
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description="Parametric style transfer and the XDoG presets on a bundled photo.")
    parser.add_argument("--out", type=Path, default=Path("out"), help="output directory (default: out)")
    args = parser.parse_args()
    run(args.out)
    report = transfer_demo(args.out)
    for line in hints(args.out, report):
        print(line)


if __name__ == "__main__":
    main()
