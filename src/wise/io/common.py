"""Pieces shared by the reading and the writing side: the path type, the formats and one-line
error text (no numerical library: the command line checks file names with them before loading any)."""

from __future__ import annotations

import os
from pathlib import Path

from wise.errors import WiseError

PathLike = str | os.PathLike[str]

READ_FORMATS = {"PNG": "PNG", "JPEG": "JPEG", "WEBP": "WebP", "TIFF": "TIFF"}
"""Pillow's names of the formats read, and how messages name them."""
IMAGE_SUFFIXES = frozenset({".png", ".jpg", ".jpeg", ".webp", ".tif", ".tiff"})
"""File extensions taken for images (folders and patterns of inputs)."""
WRITE_FORMATS = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG"}
"""Extensions of the files written, with Pillow's format names."""


def one_line(error: BaseException) -> str:
    text = str(error) or type(error).__name__
    return " ".join(text.split())


def images_in(folder: PathLike) -> list[Path]:
    """The images of a folder, sorted by name."""
    path = Path(folder)
    if not path.is_dir():
        raise WiseError(f"{path}: not a directory of images")
    found = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not found:
        raise WiseError(f"{path}: no images ({', '.join(READ_FORMATS.values())}) found")
    return found
