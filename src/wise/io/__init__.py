"""Reading and writing images as ``(1, 3, H, W)`` float tensors in [0, 1].

Reading accepts PNG, JPEG, WebP and TIFF; writing produces PNG and JPEG,
atomically. The work is split between these modules:

- :mod:`wise.io.limits`: the pixel limit and the size checks made before decoding.
- :mod:`wise.io.arrays`: sample arrays to RGB floats in [0, 1].
- :mod:`wise.io.formats`: the format-specific guarded decoders (16-bit PNG via
  pypng, TIFF via tifffile, bounded inflation, WebP header size, EXIF orientation).
- :mod:`wise.io.read`: :func:`read_image`, :func:`decode_image_bytes`,
  :func:`image_to_tensor` and the decoding context around every read.
- :mod:`wise.io.write`: :func:`tensor_to_image`, :func:`atomic_path`, :func:`write_image`.

The formats and limits load with the package; the readers and writers, which need PyTorch, on
first use, so that the command line checks file names and sizes before PyTorch loads.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from wise.io.common import IMAGE_SUFFIXES, READ_FORMATS, WRITE_FORMATS, PathLike, images_in
from wise.io.limits import (
    DEFAULT_MAX_PIXELS,
    MAX_IMAGE_BYTES,
    MAX_PIXELS_ENV,
    MAX_SAMPLES_PER_PIXEL,
    check_image_file,
    pixel_limit,
)

if TYPE_CHECKING:
    from wise.io.read import decode_image_bytes, image_to_tensor, read_image
    from wise.io.write import atomic_path, tensor_to_image, write_image, write_together

_LAZY = {
    "decode_image_bytes": "wise.io.read",
    "image_to_tensor": "wise.io.read",
    "read_image": "wise.io.read",
    "atomic_path": "wise.io.write",
    "tensor_to_image": "wise.io.write",
    "write_image": "wise.io.write",
    "write_together": "wise.io.write",
}


def __getattr__(name: str) -> object:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'wise.io' has no attribute {name!r}")


__all__ = [
    "DEFAULT_MAX_PIXELS",
    "MAX_IMAGE_BYTES",
    "MAX_PIXELS_ENV",
    "MAX_SAMPLES_PER_PIXEL",
    "IMAGE_SUFFIXES",
    "images_in",
    "READ_FORMATS",
    "WRITE_FORMATS",
    "PathLike",
    "atomic_path",
    "check_image_file",
    "write_together",
    "decode_image_bytes",
    "image_to_tensor",
    "pixel_limit",
    "read_image",
    "tensor_to_image",
    "write_image",
]
