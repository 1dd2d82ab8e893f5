"""Reading and writing images as ``(1, 3, H, W)`` float tensors in [0, 1].

Reading accepts PNG, JPEG, WebP and TIFF. The EXIF orientation is applied,
greyscale becomes RGB, and an alpha channel is composited over white (a
transparent pixel reads as white). 16-bit PNG and TIFF, greyscale or colour,
keep their precision (values are divided by 65535): Pillow reads 16-bit colour
PNG at 8 bits, so those are decoded with pypng and 16-bit colour TIFF with
tifffile.

Only regular files of at most :data:`MAX_IMAGE_BYTES` are read, and the pixel
count given by the header is checked against a limit of our own
(:func:`pixel_limit`: :data:`DEFAULT_MAX_PIXELS`, or the environment variable
:data:`MAX_PIXELS_ENV`) before anything is decoded, in every decoding path.
Pillow's own decompression-bomb check would warn or raise inside
``Image.open``, before the size can be seen, so it is switched off while one of
our reads runs: a module lock serializes the reads, and for each one
``Image.MAX_IMAGE_PIXELS`` is set to None and restored afterwards, and the
warnings and log messages of the decoders are silenced (the lock keeps the save
and restore of that global state consistent between threads); while Pillow
decodes a TIFF, file descriptor 2 points at the null device, because libtiff
prints its errors about corrupt files there, from C. Image data that inflates to
more than its header promises is refused before pypng or tifffile, which
inflate without a bound, see it.

Writing supports PNG and JPEG and is atomic: the image goes to a temporary
file in the target directory that then replaces the target, so a failure never
leaves a partial file behind.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import struct
import sys
import tempfile
import threading
import warnings
import zlib
from pathlib import Path
from typing import BinaryIO, Callable, Iterator

import numpy as np
import torch
from PIL import Image, ImageOps, UnidentifiedImageError

from wise.errors import WiseError, size_text
from wise.files import check_size, open_regular

PathLike = str | os.PathLike[str]

READ_FORMATS = {"PNG": "PNG", "JPEG": "JPEG", "WEBP": "WebP", "TIFF": "TIFF"}
WRITE_FORMATS = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG"}
DEFAULT_MAX_PIXELS = 64_000_000
"""Largest image read by default, in pixels (width x height)."""
MAX_PIXELS_ENV = "WISE_MAX_PIXELS"
"""Environment variable that replaces :data:`DEFAULT_MAX_PIXELS`."""
MAX_IMAGE_BYTES = 2 * 1000**3
"""Largest image file: a float32 RGBA TIFF at the default pixel limit is about 1 GB."""
MAX_SAMPLES_PER_PIXEL = 8
"""More samples per pixel than any photo has: a TIFF with more is refused before decoding."""

_WHAT = "image"
_HEAD_BYTES = 64
_INFLATE_BLOCK = 1 << 20
_SIXTEEN_BIT_MODES = {"I;16", "I;16L", "I;16B", "I;16N", "I"}
_TIFF_MAGIC = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")
_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_PNG_COLOUR_TYPES = {2, 4, 6}  # RGB, greyscale + alpha, RGBA: Pillow reads these at 8 bits
_PNG_PLANES = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}
_ADAM7 = ((0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2), (0, 1, 1, 2))
_TIFF_INFLATE = {8: zlib.decompressobj, 32946: zlib.decompressobj}  # Deflate ("Adobe" and old codes)
_ORIENTATIONS: dict[int, Callable[[np.ndarray], np.ndarray]] = {
    2: lambda a: a[:, ::-1],
    3: lambda a: a[::-1, ::-1],
    4: lambda a: a[::-1],
    5: lambda a: a.swapaxes(0, 1),
    6: lambda a: np.rot90(a, -1),
    7: lambda a: np.rot90(a, 2).swapaxes(0, 1),
    8: lambda a: np.rot90(a, 1),
}
_DECODE_LOCK = threading.Lock()
_DECODER_LOGGERS = ("PIL", "tifffile")
_SILENT = logging.CRITICAL + 1


def _one_line(error: BaseException) -> str:
    text = str(error) or type(error).__name__
    return " ".join(text.split())


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


def _limit(max_pixels: int | None) -> int:
    if max_pixels is None:
        return pixel_limit()
    if isinstance(max_pixels, bool) or not isinstance(max_pixels, int) or max_pixels <= 0:
        raise WiseError(f"the pixel limit must be a positive whole number, got {max_pixels!r}")
    return max_pixels


def _megapixels(count: int) -> str:
    return f"{count / 1e6:.1f}" if count >= 100_000 else f"{count / 1e6:.2g}"


def _check_pixels(shown: str, width: int, height: int, limit: int) -> None:
    count = width * height
    if count > limit:
        raise WiseError(
            f"{shown}: {size_text(width, height)} pixels ({_megapixels(count)} megapixels) is more than the limit "
            f"of {_megapixels(limit)} megapixels; reduce the image or raise the limit with --max-pixels "
            f"or {MAX_PIXELS_ENV}"
        )


def _check_not_empty(shown: str, width: int, height: int) -> None:
    if width == 0 or height == 0:
        raise WiseError(f"{shown}: the image is empty ({size_text(width, height)} pixels)")


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


def _inflate_bounded(inflater: zlib._Decompress, data: bytes, budget: int) -> int:
    """Feed ``data`` to ``inflater``; return the bytes it produced, refusing more than ``budget``."""
    produced = 0
    while True:
        out = inflater.decompress(data, min(budget - produced + 1, _INFLATE_BLOCK))
        produced += len(out)
        if produced > budget:
            raise ValueError("the compressed image data inflates to more than the image size")
        data = inflater.unconsumed_tail
        if not data and not out:
            return produced


def _inflate_segment(f: BinaryIO, count: int, inflater: zlib._Decompress, budget: int) -> int | None:
    """Inflate the next ``count`` bytes of ``f`` within ``budget``; the bytes produced, or None
    when the file ends first (the decoder reports the truncation)."""
    produced = 0
    while count > 0:
        block = f.read(min(count, _INFLATE_BLOCK))
        if not block:
            return None
        count -= len(block)
        produced += _inflate_bounded(inflater, block, budget - produced)
    return produced


def _to_float(array: np.ndarray) -> np.ndarray:
    """Integer samples scaled to [0, 1] by their bit depth; floats clipped to [0, 1]."""
    if array.dtype == np.uint8:
        out = array.astype(np.float32) / 255.0
    elif array.dtype.kind in "ui":
        out = array.astype(np.float32) / 65535.0
    elif array.dtype.kind == "f":
        out = np.nan_to_num(array.astype(np.float32), nan=0.0)
    elif array.dtype == np.bool_:
        out = array.astype(np.float32)
    else:
        raise ValueError(f"unsupported sample type {array.dtype}")
    return np.clip(out, 0.0, 1.0)


def _to_rgb(array: np.ndarray) -> np.ndarray:
    """``H x W [x C]`` floats to ``H x W x 3``, compositing alpha over white."""
    if array.ndim == 2:
        array = array[:, :, None]
    channels = array.shape[2]
    if channels in (2, 4):
        color, alpha = array[:, :, :-1], array[:, :, -1:]
        array = color * alpha + (1.0 - alpha)
    elif channels not in (1, 3):
        array = array[:, :, :3]
    if array.shape[2] == 1:
        array = np.repeat(array, 3, axis=2)
    return array


def _pillow_array(img: Image.Image) -> np.ndarray:
    """An oriented Pillow image as ``H x W x 3`` floats in [0, 1]."""
    img = ImageOps.exif_transpose(img)
    if img.mode in _SIXTEEN_BIT_MODES or img.mode == "F":
        return _to_rgb(_to_float(np.asarray(img)))
    if "transparency" in img.info or img.mode in ("RGBa", "La", "PA"):
        img = img.convert("RGBA")
    elif img.mode not in ("RGB", "L", "RGBA", "LA"):
        img = img.convert("RGB")
    return _to_rgb(_to_float(np.asarray(img)))


def _exif_orientation(f: BinaryIO) -> int:
    f.seek(0)
    try:
        with Image.open(f) as img:
            return int(img.getexif().get(0x0112, 1))
    except Exception:  # no readable EXIF: keep the image as stored
        return 1


def _oriented(array: np.ndarray, f: BinaryIO) -> np.ndarray:
    orient = _ORIENTATIONS.get(_exif_orientation(f))
    return np.ascontiguousarray(orient(array) if orient else array)


def _check_tiff_segments(f: BinaryIO, page: object) -> None:
    """Refuse Deflate-compressed TIFF segments that inflate to more than a segment can hold."""
    inflater_of = _TIFF_INFLATE.get(int(page.compression))  # type: ignore[attr-defined]
    if inflater_of is None:
        return
    sample_bytes = math.ceil(int(page.bitspersample) / 8) * int(page.samplesperpixel)  # type: ignore[attr-defined]
    image_bytes = int(page.imagewidth) * int(page.imagelength) * max(1, int(page.imagedepth))  # type: ignore[attr-defined]
    tile_bytes = int(page.tilewidth) * int(page.tilelength) * max(1, int(page.tiledepth))  # type: ignore[attr-defined]
    budget = max(image_bytes, tile_bytes) * sample_bytes
    for offset, count in zip(page.dataoffsets, page.databytecounts):  # type: ignore[attr-defined]
        f.seek(offset)
        _inflate_segment(f, count, inflater_of(), budget)


def _tifffile_array(f: BinaryIO, shown: str, limit: int) -> np.ndarray:
    """A TIFF that Pillow cannot read at full precision, via tifffile."""
    import tifffile

    f.seek(0)
    with tifffile.TiffFile(f) as tif:
        if not tif.pages:
            raise ValueError("the TIFF file contains no images")
        page = tif.pages.first
        width, height = int(page.imagewidth), int(page.imagelength)
        if width and height:
            _check_pixels(shown, width, height, limit)
        if int(page.imagedepth) > 1:
            raise ValueError(f"a TIFF volume of {page.imagedepth} slices is not an image")
        if int(page.samplesperpixel) > MAX_SAMPLES_PER_PIXEL:
            raise ValueError(f"{page.samplesperpixel} samples per pixel")
        if page.is_tiled and int(page.tilewidth) * int(page.tilelength) > max(limit, width * height):
            raise ValueError(f"tiles of {size_text(int(page.tilewidth), int(page.tilelength))} pixels")
        _check_tiff_segments(f, page)
        array = page.asarray()
        axes = page.axes
    if array.size == 0:
        return np.zeros((0, 0, 3), np.float32)
    if array.ndim == 3 and axes.startswith("S"):
        array = np.moveaxis(array, 0, -1)
    if array.ndim not in (2, 3):
        raise ValueError(f"unexpected TIFF layout {axes} {array.shape}")
    return _oriented(_to_rgb(_to_float(array)), f)


def _needs_pypng(head: bytes) -> bool:
    """Whether a file is a 16-bit PNG with colour or alpha (IHDR: bit depth, colour type)."""
    return (
        len(head) >= 26
        and head.startswith(_PNG_MAGIC)
        and head[12:16] == b"IHDR"
        and head[24] == 16
        and head[25] in _PNG_COLOUR_TYPES
    )


def _png_data_bytes(width: int, height: int, planes: int, depth: int, interlaced: bool) -> int:
    """Bytes of filtered scanlines a PNG of this size holds (one filter byte per row, per Adam7 pass)."""
    passes = _ADAM7 if interlaced else ((0, 0, 1, 1),)
    total = 0
    for x0, y0, dx, dy in passes:
        columns, rows = -(-max(0, width - x0) // dx), -(-max(0, height - y0) // dy)
        if columns and rows:
            total += rows * (1 + -(-columns * planes * depth // 8))
    return total


def _check_png_data(f: BinaryIO, head: bytes) -> None:
    """Refuse PNG image data that inflates to more than the IHDR size (pypng inflates without a bound)."""
    width, height, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", head[16:29])
    budget = _png_data_bytes(width, height, _PNG_PLANES.get(colour, 4), depth, interlace == 1)
    inflater, produced = zlib.decompressobj(), 0
    f.seek(len(_PNG_MAGIC))
    while True:
        chunk = f.read(8)
        if len(chunk) < 8:
            return  # truncated: pypng reports it
        length, kind = struct.unpack(">I4s", chunk)
        if kind == b"IEND":
            return
        if kind != b"IDAT":
            f.seek(length + 4, os.SEEK_CUR)
            continue
        inflated = _inflate_segment(f, length, inflater, budget - produced)
        if inflated is None:
            return
        produced += inflated
        f.seek(4, os.SEEK_CUR)


def _pypng_array(f: BinaryIO, head: bytes, shown: str, limit: int) -> np.ndarray:
    """A 16-bit colour PNG that Pillow would read at 8 bits, via pypng."""
    import png

    _check_png_data(f, head)
    f.seek(0)
    try:
        width, height, rows, info = png.Reader(file=f).asDirect()
        _check_pixels(shown, width, height, limit)  # from IHDR, before any row is read
        array = np.array([np.asarray(row, np.uint16) for row in rows], np.uint16)
    except (png.Error, zlib.error) as e:
        raise ValueError(_one_line(e)) from None
    planes, depth = info["planes"], info["bitdepth"]
    if array.shape != (height, width * planes):
        raise ValueError(f"expected {height} rows of {width * planes} samples, got shape {array.shape}")
    scaled = array.reshape(height, width, planes).astype(np.float32) / float(2**depth - 1)
    return _oriented(_to_rgb(np.clip(scaled, 0.0, 1.0)), f)


def _needs_tifffile(img: Image.Image) -> bool:
    """Whether Pillow would silently drop precision of a TIFF (e.g. 16-bit RGB)."""
    if img.format != "TIFF" or img.mode in _SIXTEEN_BIT_MODES or img.mode == "F":
        return False
    bits = img.tag_v2.get(258, (8,)) if hasattr(img, "tag_v2") else (8,)
    bits = bits if isinstance(bits, tuple) else (bits,)
    return any(int(b) > 8 for b in bits)


def _webp_size(head: bytes) -> tuple[int, int] | None:
    """The canvas size in a WebP header (VP8, VP8L or VP8X chunk first), or None."""
    chunk = head[12:16]
    if chunk == b"VP8 " and len(head) >= 30 and head[23:26] == b"\x9d\x01\x2a":
        return int.from_bytes(head[26:28], "little") & 0x3FFF, int.from_bytes(head[28:30], "little") & 0x3FFF
    if chunk == b"VP8L" and len(head) >= 25 and head[20] == 0x2F:
        bits = int.from_bytes(head[21:25], "little")
        return (bits & 0x3FFF) + 1, ((bits >> 14) & 0x3FFF) + 1
    if chunk == b"VP8X" and len(head) >= 30:
        return int.from_bytes(head[24:27], "little") + 1, int.from_bytes(head[27:30], "little") + 1
    return None


def _unsupported(shown: str, fmt: str) -> WiseError:
    return WiseError(f"{shown}: unsupported image format {fmt}; supported: {', '.join(READ_FORMATS.values())}")


def _decode(f: BinaryIO, shown: str, limit: int) -> np.ndarray:
    """``H x W x 3`` floats of an open image file, its pixel count checked before decoding."""
    head = f.read(_HEAD_BYTES)
    if head[:4] == b"RIFF" and head[8:12] == b"WEBP":
        # libwebp allocates the whole canvas when Pillow opens the file, so check first
        size = _webp_size(head)
        if size is None:
            raise ValueError("no image size in the WebP header")
        _check_pixels(shown, *size, limit)
    f.seek(0)
    try:
        img = Image.open(f)
    except UnidentifiedImageError:
        if not head.startswith(_TIFF_MAGIC):
            supported = ", ".join(READ_FORMATS.values())
            raise WiseError(f"{shown}: not an image in a supported format ({supported})") from None
        return _tifffile_array(f, shown, limit)
    with img:
        fmt = img.format or "unknown"
        if fmt not in READ_FORMATS:
            raise _unsupported(shown, fmt)
        width, height = img.size
        _check_not_empty(shown, width, height)
        _check_pixels(shown, width, height, limit)  # Image.open is lazy: nothing is decoded yet
        if fmt == "PNG" and _needs_pypng(head):
            return _pypng_array(f, head, shown, limit)
        if _needs_tifffile(img):
            return _tifffile_array(f, shown, limit)
        with _stderr_silenced() if fmt == "TIFF" else contextlib.nullcontext():
            img.load()
        return _pillow_array(img)


def _read(path: Path, shown: str, limit: int) -> torch.Tensor:
    """The image in the file at ``path``; messages name it ``shown``."""
    f = open_regular(path, _WHAT, MAX_IMAGE_BYTES)
    try:
        with f, _decoding():
            array = _decode(f, shown, limit)
            _check_not_empty(shown, array.shape[1], array.shape[0])
            return image_to_tensor(array)
    except WiseError:
        raise
    except PermissionError as e:
        raise WiseError(f"{shown}: cannot read the file ({e.strerror or _one_line(e)})") from None
    except MemoryError:
        raise WiseError(f"{shown}: not enough memory to decode the image; reduce the image or free memory") from None
    except Exception as e:  # decoders raise many types on malformed data; every one means the same to the user
        reason = _one_line(e).replace(str(path), shown)
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
    limit = _limit(max_pixels)
    path = Path(path)
    return _read(path, str(path), limit)


def decode_image_bytes(data: bytes, name: str, max_pixels: int | None = None) -> torch.Tensor:
    """Read image bytes (an upload) exactly as :func:`read_image` reads a file; messages name ``name``."""
    limit = _limit(max_pixels)
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise WiseError(f"{name}: expected the bytes of an image, got {type(data).__name__}")
    check_size(memoryview(data).nbytes, name, _WHAT, MAX_IMAGE_BYTES)
    try:
        fd, tmp_name = tempfile.mkstemp(prefix="wise-image-", suffix=".tmp")
    except OSError as e:
        raise WiseError(f"{name}: cannot store the image for reading ({e.strerror or _one_line(e)})") from None
    tmp = Path(tmp_name)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        return _read(tmp, name, limit)
    except OSError as e:
        raise WiseError(f"{name}: cannot store the image for reading ({e.strerror or _one_line(e)})") from None
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
    rgb = _to_rgb(_to_float(array))
    return torch.from_numpy(np.ascontiguousarray(rgb, dtype=np.float32)).permute(2, 0, 1).unsqueeze(0).contiguous()


def tensor_to_image(tensor: torch.Tensor) -> np.ndarray:
    """A ``(1, C, H, W)`` or ``(C, H, W)`` tensor in [0, 1] (C = 1 or 3) to ``H x W x C`` uint8."""
    if not isinstance(tensor, torch.Tensor):
        raise WiseError(f"expected an image tensor, got {type(tensor).__name__}")
    t = tensor.detach()
    if t.dim() == 4 and t.shape[0] == 1:
        t = t[0]
    if t.dim() != 3 or t.shape[0] not in (1, 3):
        raise WiseError(f"image must have shape (1, 3, H, W), (3, H, W) or (1, 1, H, W); got {tuple(tensor.shape)}")
    if min(t.shape[-2:]) == 0:
        raise WiseError(f"image is empty: shape {tuple(tensor.shape)}")
    t = t.to("cpu", torch.float32)
    if not torch.isfinite(t).all():
        raise WiseError("image contains NaN or infinite values")
    return (t.clamp(0.0, 1.0) * 255.0).round().to(torch.uint8).permute(1, 2, 0).numpy()


@contextlib.contextmanager
def atomic_path(path: PathLike) -> Iterator[Path]:
    """Yield a temporary path next to ``path`` that replaces ``path`` on success.

    On any error the temporary file is removed and ``path`` stays untouched.
    Raises :class:`WiseError` when the directory is missing or not writable.
    """
    target = Path(path)
    directory = target.parent
    if target.is_dir():
        raise WiseError(f"{target}: is a directory")
    if not directory.is_dir():
        raise WiseError(f"{target}: the directory {directory} does not exist")
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=directory)
    except OSError as e:
        raise WiseError(f"{target}: cannot write to {directory} ({e.strerror or _one_line(e)})") from None
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def write_image(image: torch.Tensor, path: PathLike, quality: int = 95) -> None:
    """Write a ``(1, 3, H, W)``, ``(3, H, W)`` or ``(1, 1, H, W)`` tensor in [0, 1] as 8-bit PNG or JPEG.

    The format follows the extension (.png, .jpg, .jpeg); values are clamped and
    rounded. ``quality`` (1-100) applies to JPEG. The write is atomic.
    """
    target = Path(path)
    fmt = WRITE_FORMATS.get(target.suffix.lower())
    if fmt is None:
        raise WiseError(
            f"{target}: cannot write {target.suffix or 'files without an extension'}; "
            f"supported extensions: {', '.join(WRITE_FORMATS)}"
        )
    if not isinstance(quality, int) or not 1 <= quality <= 100:
        raise WiseError(f"JPEG quality must be an integer from 1 to 100, got {quality!r}")
    array = tensor_to_image(image)
    img = Image.fromarray(array[:, :, 0] if array.shape[2] == 1 else array)
    options: dict[str, object] = {"quality": quality} if fmt == "JPEG" else {}
    try:
        with atomic_path(target) as tmp:
            img.save(tmp, format=fmt, **options)
    except OSError as e:
        raise WiseError(f"{target}: cannot write the image ({e.strerror or _one_line(e)})") from None
