"""Before/after sheets of looks at 100 %: crops of one effect's presets rendered by an earlier
commit (top row) and by this checkout (bottom row), one pixel of the render per pixel of the sheet.

Usage::

    python docs/before_after.py --base c23953e --effect watercolor --photo astronaut --size 1000 \\
        --box 190,110,390,340 -o docs/watercolor_before_after.jpg

``--photo`` is a ``skimage.data`` name or an image file, resized to ``--size`` pixels on its short
side; ``--box`` is the crop (left, top, right, bottom) in pixels of that size. The base commit is
checked out into a temporary worktree and rendered in a process of its own, with its own sources.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from PIL import Image

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
from sheet import labelled_sheet  # noqa: E402

JPEG_QUALITY = 90


def render_crops(effect_name: str, photo: str, size: int, box: tuple[int, int, int, int], out: Path) -> None:
    """Every preset of ``effect_name`` on ``photo`` at ``size``, cropped to ``box``, as PNGs in ``out``
    (with the sources that ``wise`` imports from in this process)."""
    import torch
    import torch.nn.functional as F
    from skimage import data

    from wise.effects import create
    from wise.io import image_to_tensor, read_image, write_image
    from wise.render import render

    image = image_to_tensor(getattr(data, photo)()) if hasattr(data, photo) else read_image(photo)
    factor = size / min(image.shape[-2:])
    shape = (round(image.shape[-2] * factor), round(image.shape[-1] * factor))
    image = F.interpolate(image, size=shape, mode="bicubic", align_corners=False).clamp(0.0, 1.0)
    left, top, right, bottom = box
    out.mkdir(parents=True, exist_ok=True)
    write_image(image[..., top:bottom, left:right], out / "photo.png")
    effect = create(effect_name).eval()
    for preset in effect.presets:
        with torch.no_grad():
            result = render(effect, image, effect.preset(preset)[None]).clamp(0.0, 1.0)
        write_image(result[..., top:bottom, left:right], out / f"{preset}.png")
    print(json.dumps(sorted(effect.presets)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--base", required=True, help="the commit to compare with")
    parser.add_argument("--effect", required=True)
    parser.add_argument("--photo", default="astronaut", help="a skimage.data name or an image file")
    parser.add_argument("--size", type=int, default=1000, help="short side of the render, pixels")
    parser.add_argument("--box", required=True, help="LEFT,TOP,RIGHT,BOTTOM of the crop, pixels")
    parser.add_argument("-o", "--output", type=Path, required=True)
    parser.add_argument("--render-into", type=Path, help=argparse.SUPPRESS)  # one side, in its own process
    args = parser.parse_args()
    box = tuple(int(value) for value in args.box.split(","))
    if len(box) != 4:
        parser.error("--box takes four numbers: LEFT,TOP,RIGHT,BOTTOM")
    if args.render_into is not None:
        render_crops(args.effect, args.photo, args.size, box, args.render_into)
        return

    with tempfile.TemporaryDirectory(prefix="wise-before-after-") as folder:
        base_tree = Path(folder) / "base"
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", "--quiet", str(base_tree), args.base], check=True
        )
        try:
            for side, sources in (("before", base_tree / "src"), ("after", ROOT / "src")):
                print(f"rendering {args.effect} with the sources {side} ...", flush=True)
                subprocess.run(
                    [sys.executable, __file__, *sys.argv[1:], "--render-into", str(Path(folder) / side)],
                    check=True,
                    env={**os.environ, "PYTHONPATH": str(sources)},
                    stdout=subprocess.DEVNULL,
                )
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(base_tree)], check=False)
        names = ["photo"] + sorted(path.stem for path in (Path(folder) / "after").glob("*.png") if path.stem != "photo")
        rows = [
            [(f"{name} ({side})", Image.open(Path(folder) / side / f"{name}.png").convert("RGB")) for name in names]
            for side in ("before", "after")
        ]
        cell = box[3] - box[1]
        labelled_sheet(rows, cell).save(args.output, quality=JPEG_QUALITY)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
