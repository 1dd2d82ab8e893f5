"""Reading image files and uploaded bytes as ``(1, 3, H, W)`` float tensors in [0, 1].

Reading accepts PNG, JPEG, WebP and TIFF. The EXIF orientation is applied,
greyscale becomes RGB, and an alpha channel is composited over white (a
transparent pixel reads as white).

Pillow's own decompression-bomb check would warn or raise inside
``Image.open``, before the size can be seen, so it is switched off while one of
our reads runs: a module lock serializes the reads, and for each one
``Image.MAX_IMAGE_PIXELS`` is set to None and restored afterwards, and the
warnings and log messages of the decoders are silenced (the lock keeps the save
and restore of that global state consistent between threads); while Pillow
decodes a TIFF, file descriptor 2 points at the null device, because libtiff
prints its errors about corrupt files there, from C. The pixel limit of
:mod:`wise.io.limits` replaces it, checked before decoding in every path.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import tempfile
import threading
import warnings
from pathlib import Path
from typing import BinaryIO, Iterator

import numpy as np
import torch
from PIL import Image, ImageOps, UnidentifiedImageError

from wise.errors import WiseError
from wise.files import check_size, open_regular
from wise.io.arrays import to_float, to_rgb
from wise.io.common import READ_FORMATS, PathLike, one_line
from wise.io.formats import (
    SIXTEEN_BIT_MODES,
    TIFF_MAGIC,
    needs_pypng,
    needs_tifffile,
    pypng_array,
    tifffile_array,
    webp_size,
)
from wise.io.limits import IMAGE_WHAT, MAX_IMAGE_BYTES, check_not_empty, check_pixels, resolve_limit

_WHAT = IMAGE_WHAT
_HEAD_BYTES = 64
_DECODE_LOCK = threading.Lock()
_DECODER_LOGGERS = ("PIL", "tifffile")
_SILENT = logging.CRITICAL + 1


@contextlib.contextmanager
def _decoding() -> Iterator[None]:
    """One read at a time, with Pillow's pixel check off and the decoders' warnings and log messages silenced."""
    loggers = [logging.getLogger(name) for name in _DECODER_LOGGERS]
    with _DECODE_LOCK, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        saved_limit, saved_levels = Image.MAX_IMAGE_PIXELS, [logger.level for logger in loggers]
        Image.MAX_IMAGE_PIXELS = None
        for logger in loggers:  # their modules' loggers inherit this level
            logger.setLevel(_SILENT)
        try:
            yield
        finally:
            Image.MAX_IMAGE_PIXELS = saved_limit
            for logger, level in zip(loggers, saved_levels):
                logger.setLevel(level)


@contextlib.contextmanager
def _stderr_silenced() -> Iterator[None]:
    """File descriptor 2 pointed at the null device: libtiff prints its errors there, from C."""
    try:
        sys.stderr.flush()
        saved: int | None = os.dup(2)
    except (OSError, ValueError, AttributeError):  # no stderr to silence
        saved = None
    if saved is None:
        yield
        return
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(null, 2)
        finally:
            os.close(null)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _pillow_array(img: Image.Image) -> np.ndarray:
    """An oriented Pillow image as ``H x W x 3`` floats in [0, 1]."""
    img = ImageOps.exif_transpose(img)
    if img.mode in SIXTEEN_BIT_MODES or img.mode == "F":
        return to_rgb(to_float(np.asarray(img)))
    if "transparency" in img.info or img.mode in ("RGBa", "La", "PA"):
        img = img.convert("RGBA")
    elif img.mode not in ("RGB", "L", "RGBA", "LA"):
        img = img.convert("RGB")
    return to_rgb(to_float(np.asarray(img)))


def _unsupported(shown: str, fmt: str) -> WiseError:
    return WiseError(f"{shown}: unsupported image format {fmt}; supported: {', '.join(READ_FORMATS.values())}")


def _decode(f: BinaryIO, shown: str, limit: int) -> np.ndarray:
    """``H x W x 3`` floats of an open image file, its pixel count checked before decoding."""
    head = f.read(_HEAD_BYTES)
    if head[:4] == b"RIFF" and head[8:12] == b"WEBP":
        # libwebp allocates the whole canvas when Pillow opens the file, so check first
        size = webp_size(head)
        if size is None:
            raise ValueError("no image size in the WebP header")
        check_pixels(shown, *size, limit)
    f.seek(0)
    try:
        img = Image.open(f)
    except UnidentifiedImageError:
        if not head.startswith(TIFF_MAGIC):
            supported = ", ".join(READ_FORMATS.values())
            raise WiseError(f"{shown}: not an image in a supported format ({supported})") from None
        return tifffile_array(f, shown, limit)
    with img:
        fmt = img.format or "unknown"
        if fmt not in READ_FORMATS:
            raise _unsupported(shown, fmt)
        width, height = img.size
        check_not_empty(shown, width, height)
        check_pixels(shown, width, height, limit)  # Image.open is lazy: nothing is decoded yet
        if fmt == "PNG" and needs_pypng(head):
            return pypng_array(f, head, shown, limit)
        if needs_tifffile(img):
            return tifffile_array(f, shown, limit)
        with _stderr_silenced() if fmt == "TIFF" else contextlib.nullcontext():
            img.load()
        return _pillow_array(img)


def _read(path: Path, shown: str, limit: int) -> torch.Tensor:
    """The image in the file at ``path``; messages name it ``shown``."""
    f = open_regular(path, _WHAT, MAX_IMAGE_BYTES)
    try:
        with f, _decoding():
            array = _decode(f, shown, limit)
            check_not_empty(shown, array.shape[1], array.shape[0])
            return image_to_tensor(array)
    except WiseError:
        raise
    except PermissionError as e:
        raise WiseError(f"{shown}: cannot read the file ({e.strerror or one_line(e)})") from None
    except MemoryError:
        raise WiseError(f"{shown}: not enough memory to decode the image; reduce the image or free memory") from None
    except Exception as e:  # decoders raise many types on malformed data; every one means the same to the user
        reason = one_line(e).replace(str(path), shown)
        raise WiseError(f"{shown}: corrupt or unreadable image data ({reason})") from None


def read_image(path: PathLike, max_pixels: int | None = None) -> torch.Tensor:
    """Read an image file as a ``(1, 3, H, W)`` float32 tensor in [0, 1].

    Supports PNG, JPEG, WebP and TIFF. Applies the EXIF orientation, turns
    greyscale into RGB and composites alpha over white. ``max_pixels`` defaults
    to :func:`pixel_limit`; a larger image is refused from its header, before
    decoding. Raises :class:`WiseError` naming the file, and nothing else, for
    any file content: missing, not a regular file, too large, not a supported
    image, corrupt or empty.
    """
    limit = resolve_limit(max_pixels)
    path = Path(path)
    return _read(path, str(path), limit)


def decode_image_bytes(data: bytes, name: str, max_pixels: int | None = None) -> torch.Tensor:
    """Read image bytes (an upload) exactly as :func:`read_image` reads a file; messages name ``name``."""
    limit = resolve_limit(max_pixels)
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise WiseError(f"{name}: expected the bytes of an image, got {type(data).__name__}")
    check_size(memoryview(data).nbytes, name, _WHAT, MAX_IMAGE_BYTES)
    try:
        fd, tmp_name = tempfile.mkstemp(prefix="wise-image-", suffix=".tmp")
    except OSError as e:
        raise WiseError(f"{name}: cannot store the image for reading ({e.strerror or one_line(e)})") from None
    tmp = Path(tmp_name)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        return _read(tmp, name, limit)
    except OSError as e:
        raise WiseError(f"{name}: cannot store the image for reading ({e.strerror or one_line(e)})") from None
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()


def image_to_tensor(array: np.ndarray) -> torch.Tensor:
    """``H x W``, ``H x W x 1|2|3|4`` uint8, uint16 or float array to ``(1, 3, H, W)`` float32.

    uint8 is divided by 255, other integers by 65535, floats are taken as [0, 1];
    alpha is composited over white.
    """
    array = np.asarray(array)
    if array.ndim not in (2, 3) or (array.ndim == 3 and array.shape[2] not in (1, 2, 3, 4)):
        raise WiseError(f"expected an H x W or H x W x C image array, got shape {array.shape}")
    rgb = to_rgb(to_float(array))
    return torch.from_numpy(np.ascontiguousarray(rgb, dtype=np.float32)).permute(2, 0, 1).unsqueeze(0).contiguous()
