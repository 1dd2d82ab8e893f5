"""Assemble the photo folders the built-in prediction models were trained and measured on.

    apt-get download mate-backgrounds gnome-backgrounds ukui-wallpapers
    apt-get download lomiri-wallpapers-16.04 lomiri-wallpapers-20.04
    python benchmarks/training_photos.py --debs . --out photos [--portrait portrait.png]

writes ``photos/train`` (the ``skimage.data`` photos listed in :data:`SKIMAGE_TRAINING`, and the
raster pictures of the three Debian packages: mate-backgrounds, GPL-2+; gnome-backgrounds,
CC BY-SA 3.0; ukui-wallpapers, CC BY-SA 3.0) and ``photos/eval``, photos never used in
training: ``skimage.data`` astronaut, chelsea and coffee; the photos of people, animals,
objects and landscapes among the Lomiri wallpapers (:data:`LOMIRI_EVALUATION`; CC BY 4.0 and
CC BY-SA 4.0) when those packages were downloaded; and a portrait if ``--portrait`` names one.
Vector pictures (SVG) are left out: ``wise`` reads raster images.
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
LOMIRI = ("lomiri-wallpapers-16.04", "lomiri-wallpapers-20.04")
LOMIRI_EVALUATION = (
    "Bridge_by_Sander_Klootwijk", "Dragonfly_by_Bolly", "Kleiber_by_Lukas_Baubkus", "Picture_0B_by_freespace",
    "Picture_1A_by_freespace", "Wine_by_Jakkub_Mede", "aitzgorri_by_Aitzol_Berasategi", "free_by_Peter_Nerlich",
    "friends_by_Aitzol_Berasategi", "greentock_by_Peter_Nerlich", "life_by_Aitzol_Berasategi",
    "picosdeeuropa_by_Aitzol_Berasategi", "seeding_by_Clements_Engelhardt", "sunset_by_Aitzol_Berasategi",
)  # fmt: skip
"""The photos of people, animals, objects and landscapes among the Lomiri wallpapers (the abstract
pictures are left out), for ``eval/``: no model is trained on them."""


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
    for package in LOMIRI:
        debs = sorted(Path(args.debs).glob(f"{package}_*.deb"))
        if not debs:
            continue
        with tempfile.TemporaryDirectory() as tmp:
            _extract(debs[-1], Path(tmp))
            for path in sorted((Path(tmp) / "usr/share/backgrounds").glob("*.jpg")):
                if path.stem in LOMIRI_EVALUATION:
                    shutil.copy(path, out / "eval" / path.name)
    count = sum(1 for p in (out / "train").rglob("*") if p.is_file())
    print(f"{out / 'train'}: {count} photos; {out / 'eval'}: {len(list((out / 'eval').iterdir()))} photos")


if __name__ == "__main__":
    main()
