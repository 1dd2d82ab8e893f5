"""Test photos written as files."""

from __future__ import annotations

from pathlib import Path

from PIL import Image
from skimage import data


def astronaut_png(path: Path, width: int, height: int) -> Path:
    """``skimage.data.astronaut()`` resized to ``width`` x ``height``, saved as PNG at ``path``."""
    Image.fromarray(data.astronaut()).resize((width, height), Image.Resampling.BILINEAR).save(path)
    return path


PAIR_PHOTOS = ("astronaut", "coffee", "chelsea", "rocket", "camera", "immunohistochemistry")
"""skimage photos of the paired test sets: four for training, two for testing."""


def xdog_pairs(root: Path, size: int = 64, parameter: str = "shading", inside: float = 0.8) -> Path:
    """A paired set ``root/{train,test}/{A,B,regions}`` whose targets are XDoG's ``portrait``
    preset with ``parameter`` set to ``inside`` where the photo is dark (luminance below
    one half: the region, a rule of the pixels), and the ``task.json`` that says so."""
    import json

    import numpy as np
    import torch

    from wise import effects
    from wise.effects.base import window_scale

    effect = effects.create("xdog")
    preset = effect.preset("portrait")
    index = effect.param_names.index(parameter)
    spec = effect.param_specs[index]
    for number, name in enumerate(PAIR_PHOTOS):
        split = "train" if number < 4 else "test"
        for folder in ("A", "B", "regions"):
            (root / split / folder).mkdir(parents=True, exist_ok=True)
        picture = getattr(data, name)()
        if picture.ndim == 2:
            picture = np.stack([picture] * 3, axis=-1)
        photo = Image.fromarray(picture[..., :3]).resize((size, size), Image.Resampling.BILINEAR)
        photo.save(root / split / "A" / f"{name}.png")
        tensor = torch.from_numpy(np.asarray(photo).copy()).permute(2, 0, 1)[None] / 255.0
        dark = tensor.mean(dim=1, keepdim=True) < 0.5
        masks = preset.view(1, -1, 1, 1).repeat(1, 1, size, size)
        masks[:, index : index + 1][dark] = (inside - spec.min) / (spec.max - spec.min) - 0.5
        region = (dark[0, 0].numpy() * 255).astype(np.uint8)
        with torch.no_grad():
            target = effect(tensor, masks, scale=window_scale(size, size))  # as training renders them
        target_array = (target[0].permute(1, 2, 0).numpy() * 255.0).round().astype(np.uint8)
        Image.fromarray(target_array).save(root / split / "B" / f"{name}.png")
        Image.fromarray(region).save(root / split / "regions" / f"{name}.png")
    task = {
        "task": "dark",
        "effect": "xdog",
        "preset": "portrait",
        "parameter": parameter,
        "inside": inside,
        "preset_value": effect.presets["portrait"][parameter],
    }
    (root / "task.json").write_text(json.dumps(task))
    return root


def drawing_pairs(root: Path, size: int = 64, layout: str = "separate") -> Path:
    """A paired set of :data:`PAIR_PHOTOS` and the synthetic artist's drawings of them
    (:func:`wise.train.drawing.draw`), four for training and two for testing. ``layout``:
    ``separate`` (``root/<split>/{A,B}``) or ``apdrawing`` (APDrawingDB as distributed:
    ``root/data/<split>/<name>.png`` with photo and drawing side by side, and the unused
    ``landmark/`` and ``mask/`` folders)."""
    import numpy as np
    import torch

    from wise.train.drawing import draw

    for number, name in enumerate(PAIR_PHOTOS):
        split = "train" if number < 4 else "test"
        picture = getattr(data, name)()
        if picture.ndim == 2:
            picture = np.stack([picture] * 3, axis=-1)
        photo = Image.fromarray(picture[..., :3]).resize((size, size), Image.Resampling.BILINEAR)
        tensor = torch.from_numpy(np.asarray(photo).copy()).permute(2, 0, 1)[None] / 255.0
        drawing = Image.fromarray((draw(tensor)[0].permute(1, 2, 0).numpy() * 255.0).round().astype(np.uint8))
        if layout == "separate":
            for folder, image in (("A", photo), ("B", drawing)):
                (root / split / folder).mkdir(parents=True, exist_ok=True)
                image.save(root / split / folder / f"{name}.png")
        else:
            (root / "data" / split).mkdir(parents=True, exist_ok=True)
            side_by_side = Image.new("RGB", (2 * size, size))
            side_by_side.paste(photo, (0, 0))
            side_by_side.paste(drawing, (size, 0))
            side_by_side.save(root / "data" / split / f"{name}.png")
    if layout == "apdrawing":
        for folder in ("landmark/ALL", "mask/ALL"):
            (root / folder).mkdir(parents=True, exist_ok=True)
        (root / "landmark" / "ALL" / "astronaut.txt").write_text("10 10\n")
    return root
