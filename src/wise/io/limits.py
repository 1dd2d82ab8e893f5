"""Limits on what is read, checked before anything is decoded.

Only regular files of at most :data:`MAX_IMAGE_BYTES` are read, and the pixel
count given by the header is checked against a limit of our own
(:func:`pixel_limit`: :data:`DEFAULT_MAX_PIXELS`, or the environment variable
:data:`MAX_PIXELS_ENV`) before anything is decoded, in every decoding path.
"""

from __future__ import annotations

import os

from wise.errors import WiseError, size_text

DEFAULT_MAX_PIXELS = 64_000_000
"""Largest image read by default, in pixels (width x height)."""
MAX_PIXELS_ENV = "WISE_MAX_PIXELS"
"""Environment variable that replaces :data:`DEFAULT_MAX_PIXELS`."""
MAX_IMAGE_BYTES = 2 * 1000**3
"""Largest image file: a float32 RGBA TIFF at the default pixel limit is about 1 GB."""
MAX_SAMPLES_PER_PIXEL = 8
IMAGE_WHAT = "image"
"""How messages name an image file."""
"""More samples per pixel than any photo has: a TIFF with more is refused before decoding."""


def pixel_limit() -> int:
    """The largest number of pixels an image may have: :data:`MAX_PIXELS_ENV` if set, else the default.

    The variable is read on each call; an empty value counts as unset.
    """
    value = os.environ.get(MAX_PIXELS_ENV, "")
    if not value.strip():
        return DEFAULT_MAX_PIXELS
    try:
        limit = int(value.strip())
    except ValueError:
        limit = 0
    if limit <= 0:
        raise WiseError(
            f"{MAX_PIXELS_ENV}={value!r}: not a positive whole number of pixels; unset it or set e.g. 100000000"
        )
    return limit


def resolve_limit(max_pixels: int | None) -> int:
    """``max_pixels`` checked, or :func:`pixel_limit` when it is None."""
    if max_pixels is None:
        return pixel_limit()
    if isinstance(max_pixels, bool) or not isinstance(max_pixels, int) or max_pixels <= 0:
        raise WiseError(f"the pixel limit must be a positive whole number, got {max_pixels!r}")
    return max_pixels


def _megapixels(count: int) -> str:
    return f"{count / 1e6:.1f}" if count >= 100_000 else f"{count / 1e6:.2g}"


def check_pixels(shown: str, width: int, height: int, limit: int) -> None:
    count = width * height
    if count > limit:
        raise WiseError(
            f"{shown}: {size_text(width, height)} pixels ({_megapixels(count)} megapixels) is more than the limit "
            f"of {_megapixels(limit)} megapixels; reduce the image or raise the limit with --max-pixels "
            f"or {MAX_PIXELS_ENV}"
        )


def check_not_empty(shown: str, width: int, height: int) -> None:
    if width == 0 or height == 0:
        raise WiseError(f"{shown}: the image is empty ({size_text(width, height)} pixels)")


def check_image_file(path: str | os.PathLike[str]) -> None:
    """The checks :func:`wise.io.read_image` makes before opening ``path`` (it exists, is a
    regular, readable file, not empty, at most :data:`MAX_IMAGE_BYTES`), with its messages, for
    a command to make before it loads anything."""
    from wise.files import regular_file

    regular_file(path, IMAGE_WHAT, MAX_IMAGE_BYTES)
