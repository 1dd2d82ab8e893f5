"""Assemble the photo folders the built-in prediction models were trained and measured on.

    apt-get download mate-backgrounds gnome-backgrounds ukui-wallpapers
    python benchmarks/training_photos.py --debs . --out photos

writes ``photos/train`` (the ``skimage.data`` photos listed in :data:`SKIMAGE_TRAINING`, and the
raster pictures of the three Debian packages: mate-backgrounds, GPL-2+; gnome-backgrounds,
CC BY-SA 3.0; ukui-wallpapers, CC BY-SA 3.0) and ``photos/eval`` (photos never used in
training: ``skimage.data`` astronaut, chelsea and coffee, and a portrait if ``--portrait`` names
one). Vector pictures (SVG) are left out: ``wise`` reads raster images.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image
from skimage import data

SKIMAGE_TRAINING = (
    "brick", "camera", "cell", "clock", "coins", "grass", "gravel", "hubble_deep_field",
    "immunohistochemistry", "moon", "retina", "rocket",
)  # fmt: skip
SKIMAGE_EVALUATION = ("astronaut", "chelsea", "coffee")
PACKAGES = {
    "mate": ("mate-backgrounds", "usr/share/backgrounds/mate", "**/*"),
    "gnome": ("gnome-backgrounds", "usr/share/backgrounds/gnome", "*.webp"),
    "ukui": ("ukui-wallpapers", "usr/share/backgrounds", "*"),
}
RASTER = {".jpg", ".jpeg", ".png", ".webp"}


def _save(name: str, folder: Path) -> None:
    array = getattr(data, name)()
    if array.ndim == 2:
        array = np.stack([array] * 3, axis=-1)
    Image.fromarray(array).save(folder / f"{name}.png")


def _extract(deb: Path, into: Path) -> None:
    subprocess.run(["dpkg-deb", "-x", str(deb), str(into)], check=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--debs", required=True, help="folder with the three downloaded .deb files")
    parser.add_argument("--out", required=True, help="folder to write train/ and eval/ into")
    parser.add_argument("--portrait", help="a portrait photo to add to eval/")
    args = parser.parse_args()
    out = Path(args.out)
    (out / "train" / "skimage").mkdir(parents=True, exist_ok=True)
    (out / "eval").mkdir(parents=True, exist_ok=True)
    for name in SKIMAGE_TRAINING:
        _save(name, out / "train" / "skimage")
    for name in SKIMAGE_EVALUATION:
        _save(name, out / "eval")
    if args.portrait:
        shutil.copy(args.portrait, out / "eval" / Path(args.portrait).name)
    for folder, (package, where, pattern) in PACKAGES.items():
        debs = sorted(Path(args.debs).glob(f"{package}_*.deb"))
        if not debs:
            raise SystemExit(f"{args.debs}: no {package}_*.deb; run apt-get download {package}")
        with tempfile.TemporaryDirectory() as tmp:
            _extract(debs[-1], Path(tmp))
            target = out / "train" / folder
            for path in sorted((Path(tmp) / where).glob(pattern)):
                if path.is_file() and path.suffix.lower() in RASTER:
                    relative = path.relative_to(Path(tmp) / where)
                    (target / relative.parent).mkdir(parents=True, exist_ok=True)
                    shutil.copy(path, target / relative)
    count = sum(1 for p in (out / "train").rglob("*") if p.is_file())
    print(f"{out / 'train'}: {count} photos; {out / 'eval'}: {len(list((out / 'eval').iterdir()))} photos")


if __name__ == "__main__":
    main()
