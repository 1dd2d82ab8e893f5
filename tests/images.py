"""Test photos written as files."""

from __future__ import annotations

from pathlib import Path

from PIL import Image
from skimage import data


def astronaut_png(path: Path, width: int, height: int) -> Path:
    """``skimage.data.astronaut()`` resized to ``width`` x ``height``, saved as PNG at ``path``."""
    Image.fromarray(data.astronaut()).resize((width, height), Image.Resampling.BILINEAR).save(path)
    return path
