"""Format-specific decoding, guarded against oversized and malicious files.

16-bit PNG and TIFF, greyscale or colour, keep their precision (values are
divided by 65535): Pillow reads 16-bit colour PNG at 8 bits, so those are
decoded with pypng and 16-bit colour TIFF with tifffile. Both paths apply the
EXIF orientation themselves and check the pixel count from the header before
any pixel is decoded. Image data that inflates to more than its header
promises is refused before pypng or tifffile, which inflate without a bound,
see it. The WebP canvas size is read from the header, because libwebp
allocates the whole canvas as soon as Pillow opens the file.
"""

from __future__ import annotations

import math
import os
import struct
import zlib
from typing import BinaryIO, Callable

import numpy as np
from PIL import Image

from wise.errors import size_text
from wise.io.arrays import to_float, to_rgb
from wise.io.common import one_line
from wise.io.limits import MAX_SAMPLES_PER_PIXEL, check_pixels

SIXTEEN_BIT_MODES = {"I;16", "I;16L", "I;16B", "I;16N", "I"}
TIFF_MAGIC = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")
_INFLATE_BLOCK = 1 << 20
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


def tifffile_array(f: BinaryIO, shown: str, limit: int) -> np.ndarray:
    """A TIFF that Pillow cannot read at full precision, via tifffile."""
    import tifffile

    f.seek(0)
    with tifffile.TiffFile(f) as tif:
        if not tif.pages:
            raise ValueError("the TIFF file contains no images")
        page = tif.pages.first
        width, height = int(page.imagewidth), int(page.imagelength)
        if width and height:
            check_pixels(shown, width, height, limit)
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
    return _oriented(to_rgb(to_float(array)), f)


def needs_tifffile(img: Image.Image) -> bool:
    """Whether Pillow would silently drop precision of a TIFF (e.g. 16-bit RGB)."""
    if img.format != "TIFF" or img.mode in SIXTEEN_BIT_MODES or img.mode == "F":
        return False
    bits = img.tag_v2.get(258, (8,)) if hasattr(img, "tag_v2") else (8,)
    bits = bits if isinstance(bits, tuple) else (bits,)
    return any(int(b) > 8 for b in bits)


def needs_pypng(head: bytes) -> bool:
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


def pypng_array(f: BinaryIO, head: bytes, shown: str, limit: int) -> np.ndarray:
    """A 16-bit colour PNG that Pillow would read at 8 bits, via pypng."""
    import png

    _check_png_data(f, head)
    f.seek(0)
    try:
        width, height, rows, info = png.Reader(file=f).asDirect()
        check_pixels(shown, width, height, limit)  # from IHDR, before any row is read
        array = np.array([np.asarray(row, np.uint16) for row in rows], np.uint16)
    except (png.Error, zlib.error) as e:
        raise ValueError(one_line(e)) from None
    planes, depth = info["planes"], info["bitdepth"]
    if array.shape != (height, width * planes):
        raise ValueError(f"expected {height} rows of {width * planes} samples, got shape {array.shape}")
    scaled = array.reshape(height, width, planes).astype(np.float32) / float(2**depth - 1)
    return _oriented(to_rgb(np.clip(scaled, 0.0, 1.0)), f)


def webp_size(head: bytes) -> tuple[int, int] | None:
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
