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
"""

from __future__ import annotations

from wise.io.common import PathLike
from wise.io.limits import (
    DEFAULT_MAX_PIXELS,
    MAX_IMAGE_BYTES,
    MAX_PIXELS_ENV,
    MAX_SAMPLES_PER_PIXEL,
    pixel_limit,
)
from wise.io.read import IMAGE_SUFFIXES, READ_FORMATS, decode_image_bytes, image_to_tensor, read_image
from wise.io.write import WRITE_FORMATS, atomic_path, tensor_to_image, write_image, write_together

__all__ = [
    "DEFAULT_MAX_PIXELS",
    "MAX_IMAGE_BYTES",
    "MAX_PIXELS_ENV",
    "MAX_SAMPLES_PER_PIXEL",
    "IMAGE_SUFFIXES",
    "READ_FORMATS",
    "WRITE_FORMATS",
    "PathLike",
    "atomic_path",
    "write_together",
    "decode_image_bytes",
    "image_to_tensor",
    "pixel_limit",
    "read_image",
    "tensor_to_image",
    "write_image",
]
